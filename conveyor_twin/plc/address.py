"""Where a PLC server listens: ``[HOST:]PORT`` (``--opcua``, ``--modbus``)."""

from typing import Tuple

#: Host a server binds when the address names none (this machine only).
DEFAULT_HOST = '127.0.0.1'


class PlcServerError(ValueError):
    """A PLC server cannot start: a bad address, or the port cannot be bound."""


def parse_address(text: str, *, option: str = 'address') -> Tuple[str, int]:
    """Return ``(host, port)`` of ``'[HOST:]PORT'``; the host defaults to 127.0.0.1.

    An IPv6 host is written in brackets (``[::1]:4840``); port 0 lets the server pick a free
    one.

    :param option: what the text is, for the error (``'--opcua'``).
    :raises PlcServerError: naming the text and the expected form.
    """
    text = str(text).strip()
    host, port_text = DEFAULT_HOST, text
    if '://' in text:
        raise PlcServerError(f'{option} {text!r}: expected [HOST:]PORT, not a URL '
                             '(e.g. 4840 or 0.0.0.0:4840)')
    if text.startswith('['):
        end = text.find(']')
        if end < 0 or not text[end + 1:].startswith(':'):
            raise PlcServerError(f'{option} {text!r}: expected [HOST:]PORT, an IPv6 host in '
                                 'brackets, e.g. [::1]:4840')
        host, port_text = text[1:end], text[end + 2:]
    elif ':' in text:
        host, _, port_text = text.rpartition(':')
        if ':' in host:
            raise PlcServerError(f'{option} {text!r}: write an IPv6 host in brackets, e.g. '
                                 '[::1]:4840')
    host = host or DEFAULT_HOST  # ':4840' as '4840'
    if not port_text.isdigit() or not 0 <= int(port_text) <= 65535:
        raise PlcServerError(f'{option} {text!r}: port {port_text!r} is not an integer in '
                             '[0, 65535] (expected [HOST:]PORT; 0 picks a free port)')
    return host, int(port_text)
