"""Security of the twin's OPC UA server: the policy, its certificate, its users.

:class:`OpcUaSecurity` says what the server asks of a client: ``Basic256Sha256`` with
``SignAndEncrypt`` (the default; ``None``, no encryption, only when asked for), an optional
user with a password (then anonymous clients and every other user are refused) and a
read-only mode. The server's certificate and key are created on the first start in
``cert_dir`` (default: a folder of the user, :func:`default_cert_dir`) and reused while they
are valid (same application URI, at least a day left), so a client that trusted the server
once keeps trusting it. Client certificates are not checked against a trust list: any
application certificate opens an encrypted channel, and access is controlled by the user and
password (set one whenever the server listens beyond 127.0.0.1).

No ROS imports.
"""

from dataclasses import dataclass
import datetime
import hmac
import ipaddress
import os
from pathlib import Path
import socket
from typing import Any, List, Optional, Tuple

from asyncua.crypto import cert_gen
from asyncua.crypto.permission_rules import User, UserRole
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID

#: The policies a server can offer.
POLICIES = ('Basic256Sha256', 'None')
#: The server's OPC UA application URI (in its certificate and its endpoints).
APPLICATION_URI = 'urn:conveyor-twin:server'
#: File names of the server's certificate (DER) and private key (PEM) in ``cert_dir``.
CERT_FILE = 'server_cert.der'
KEY_FILE = 'server_key.pem'
#: Validity of a generated certificate [days]; one with less than a day left is replaced.
CERT_DAYS = 3650
_MIN_LEFT = datetime.timedelta(days=1)


@dataclass(frozen=True)
class OpcUaSecurity:
    """What the OPC UA server asks of its clients.

    :param policy: ``'Basic256Sha256'`` (SignAndEncrypt) or ``'None'`` (no encryption).
    :param cert_dir: folder of the server's certificate and key; '' for
        :func:`default_cert_dir`.
    :param user: the one user name accepted; '' for anonymous access.
    :param password: that user's password (required with a user).
    :param read_only: every write refused (the variables are shown read-only to clients).
    """

    policy: str = 'Basic256Sha256'
    cert_dir: str = ''
    user: str = ''
    password: str = ''
    read_only: bool = False

    def __post_init__(self) -> None:
        if self.policy not in POLICIES:
            raise ValueError(f'OPC UA security: policy {self.policy!r} is not one of '
                             f'{", ".join(POLICIES)}')
        if bool(self.user) != bool(self.password):
            given = 'set' if self.password else 'empty'
            raise ValueError('OPC UA security: a user needs a password and a password a user '
                             f'(user {self.user!r}, password {given})')

    @property
    def encrypted(self) -> bool:
        """True if clients must sign and encrypt (the server needs a certificate)."""
        return self.policy != 'None'


def default_cert_dir() -> Path:
    """Return the per-user folder of the server certificate
    (``$XDG_DATA_HOME/conveyor_twin/opcua``, else ``~/.local/share/conveyor_twin/opcua``)."""
    base = (os.environ.get('XDG_DATA_HOME')
            or os.path.join(os.path.expanduser('~'), '.local', 'share'))
    return Path(base) / 'conveyor_twin' / 'opcua'


def server_certificate(cert_dir: str, host: str) -> Tuple[Path, Path]:
    """Return the paths of a valid certificate (DER) and key (PEM) in ``cert_dir``, creating
    them (and the folder, mode 0700) if they are missing, expired, for another application
    URI or do not belong together.

    :param cert_dir: the folder; '' for :func:`default_cert_dir`.
    :param host: the address the server binds (put in the certificate as IP or DNS name).
    :raises OSError: if the folder or the files cannot be written.
    """
    folder = Path(cert_dir) if cert_dir else default_cert_dir()
    folder.mkdir(mode=0o700, parents=True, exist_ok=True)
    cert_path, key_path = folder / CERT_FILE, folder / KEY_FILE
    if not _valid(cert_path, key_path, host):
        _generate(cert_path, key_path, host)
    return cert_path, key_path


def _valid(cert_path: Path, key_path: Path, host: str) -> bool:
    """True if the pair exists, belongs together, names our URI and ``host`` and has a day
    left."""
    try:
        cert = x509.load_der_x509_certificate(cert_path.read_bytes())
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except (OSError, ValueError, TypeError):
        return False
    if cert.public_key().public_numbers() != key.public_key().public_numbers():
        return False
    now = datetime.datetime.now(datetime.timezone.utc)
    if cert.not_valid_after_utc - now < _MIN_LEFT or cert.not_valid_before_utc > now:
        return False
    try:
        names = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    except x509.ExtensionNotFound:
        return False
    hosts = {str(a) for a in names.get_values_for_type(x509.IPAddress)}
    hosts.update(names.get_values_for_type(x509.DNSName))
    return (APPLICATION_URI in names.get_values_for_type(x509.UniformResourceIdentifier)
            and _host_name(host) in hosts)


def _generate(cert_path: Path, key_path: Path, host: str) -> None:
    """Write a new self-signed application certificate and its key (key mode 0600)."""
    key = cert_gen.generate_private_key()
    names: List[x509.GeneralName] = [x509.UniformResourceIdentifier(APPLICATION_URI),
                                     x509.DNSName('localhost'),
                                     x509.DNSName(socket.gethostname())]
    for address in sorted({_host_name(host), '127.0.0.1'}):
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(address)))
        except ValueError:
            names.append(x509.DNSName(address))
    cert = cert_gen.generate_self_signed_app_certificate(
        key, 'conveyor_twin', {'organizationName': 'conveyor_twin'}, names,
        extended=[ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH],
        days=CERT_DAYS)
    tmp_key = key_path.with_suffix('.tmp')
    fd = os.open(tmp_key, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, 'wb') as f:
        f.write(cert_gen.dump_private_key_as_pem(key))
    tmp_cert = cert_path.with_suffix('.tmp')
    tmp_cert.write_bytes(cert.public_bytes(serialization.Encoding.DER))
    os.replace(tmp_key, key_path)
    os.replace(tmp_cert, cert_path)


def _host_name(host: str) -> str:
    """``host`` as a certificate names it (an IP address in its normal form)."""
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        return host


class TwinUserManager:
    """The users of the server (asyncua's ``UserManager`` interface).

    Without a configured user every client is an ordinary user (anonymous access); with one,
    only that user name with its password is accepted (compared in constant time).
    """

    def __init__(self, security: OpcUaSecurity) -> None:
        self._user = security.user
        self._password = security.password.encode()

    def get_user(self, iserver: Any, username: Optional[str] = None,
                 password: Optional[str] = None, certificate: Any = None) -> Optional[User]:
        """Return the client's user, or None to refuse the session."""
        if not self._user:
            return User(role=UserRole.User)
        if username is None or password is None:
            return None
        name_ok = hmac.compare_digest(username.encode(), self._user.encode())
        password_ok = hmac.compare_digest(password.encode(), self._password)
        if name_ok and password_ok:
            return User(role=UserRole.User, name=username)
        return None
