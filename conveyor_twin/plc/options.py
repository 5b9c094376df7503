"""What a twin's PLC servers are asked for: addresses, access and OPC UA security.

:class:`PlcOptions` is what ``conveyor-twin run --opcua/--modbus``, ``LockstepTwin(opcua=...,
modbus=...)`` and the plant's cells hand to :func:`conveyor_twin.plc.attach.attach_plc`.
Addresses are ``[HOST:]PORT`` strings (host 127.0.0.1 by default; port 0 picks a free port);
an empty address serves nothing of that protocol.
"""

from dataclasses import dataclass, replace
import os
from typing import Optional

#: The OPC UA security policies a server offers (``None`` only when asked for explicitly).
SECURITY_POLICIES = ('Basic256Sha256', 'None')
#: Environment variable holding the OPC UA password (never a command-line argument).
PASSWORD_ENV = 'CONVEYOR_TWIN_OPCUA_PASSWORD'


@dataclass(frozen=True)
class PlcOptions:
    """The PLC servers of one twin.

    :param opcua: ``[HOST:]PORT`` of the OPC UA server; '' for none.
    :param modbus: ``[HOST:]PORT`` of the Modbus TCP server; '' for none.
    :param read_only: refuse every write (setpoints, targets, the lockstep handshake).
    :param security: OPC UA security policy: ``Basic256Sha256`` (sign and encrypt, the
        default) or ``None``.
    :param user: OPC UA user name; '' for anonymous access.
    :param password: the user's password (from :data:`PASSWORD_ENV` on the command line).
    :param cert_dir: folder of the OPC UA server's certificate and key (created on first
        start, reused after); '' for the default per-user folder.
    """

    opcua: str = ''
    modbus: str = ''
    read_only: bool = False
    security: str = 'Basic256Sha256'
    user: str = ''
    password: str = ''
    cert_dir: str = ''

    def __post_init__(self) -> None:
        for name in ('opcua', 'modbus', 'user', 'password', 'cert_dir'):
            value = getattr(self, name)
            if not isinstance(value, str):
                raise ValueError(f'PLC options: {name} {value!r} is not a string')
        if self.security not in SECURITY_POLICIES:
            raise ValueError(f'PLC options: security {self.security!r} is not one of '
                             f'{", ".join(SECURITY_POLICIES)}')
        if self.password and not self.user:
            raise ValueError('PLC options: a password without a user (give the user too)')
        if self.user and not self.password:
            raise ValueError(f'PLC options: user {self.user!r} without a password (set '
                             f'{PASSWORD_ENV})')

    @property
    def any(self) -> bool:
        """True if any server is asked for."""
        return bool(self.opcua or self.modbus)

    def for_cell(self, index: int) -> 'PlcOptions':
        """Return these options with both ports raised by ``index`` (cell ``index`` of a plant
        serves at BASE + index); a protocol without an address stays off.

        Base port 0: every cell picks a free port.

        :raises ValueError: if a port would leave [1, 65535].
        """
        return replace(self, opcua=_offset(self.opcua, index, 'opcua'),
                       modbus=_offset(self.modbus, index, 'modbus'))


def options_from_env(opcua: Optional[str], modbus: Optional[str], *, read_only: bool = False,
                     security: str = 'Basic256Sha256', user: str = '',
                     cert_dir: str = '') -> PlcOptions:
    """Return :class:`PlcOptions` with the password taken from :data:`PASSWORD_ENV`.

    :raises ValueError: on an invalid combination (the message names it).
    """
    password = os.environ.get(PASSWORD_ENV, '') if user else ''
    return PlcOptions(opcua=opcua or '', modbus=modbus or '', read_only=read_only,
                      security=security, user=user, password=password, cert_dir=cert_dir)


def _offset(address: str, index: int, name: str) -> str:
    if not address:
        return ''
    host, sep, port_text = address.rpartition(':')
    try:
        port = int(port_text)
    except ValueError:
        raise ValueError(f'PLC options: {name} address {address!r}: port {port_text!r} is not '
                         'an integer') from None
    if port == 0:  # every cell picks a free port of its own
        return address
    if not 0 <= port + index <= 65535:
        raise ValueError(f'PLC options: {name} port {port} + cell {index} = {port + index} is '
                         'outside [1, 65535]')
    return f'{host}{sep}{port + index}'
