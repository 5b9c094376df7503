"""The Foxglove view's front door: both names of the Foxglove WebSocket protocol v1.

``foxglove-sdk`` (0.30) accepts only the WebSocket subprotocol ``foxglove.sdk.v1`` and answers
any other handshake with a bare HTTP 400; Lichtblick and Foxglove releases before the SDK
offer ``foxglove.websocket.v1``, the same protocol under its former name (the messages are
identical). This proxy listens where the view was asked to, the SDK's server listens on a free
loopback port behind it. For each connection it reads the HTTP upgrade request: one offering
``foxglove.sdk.v1`` goes through unchanged; one offering only ``foxglove.websocket.v1`` is
forwarded as ``foxglove.sdk.v1`` and the server's answer is handed back naming
``foxglove.websocket.v1``; anything else is refused with HTTP 400 and a text that names both
accepted subprotocols (the refusal is counted). After the handshake the bytes are copied
both ways unchanged by two threads per connection, which block only on their own sockets: a
slow client slows its own copy, and the SDK's bounded per-client backlog drops for it, never
the twin.
"""

import socket
import threading
from typing import Callable, List, Optional, Tuple

from conveyor_twin.health import Health

SDK_SUBPROTOCOL = 'foxglove.sdk.v1'
LEGACY_SUBPROTOCOL = 'foxglove.websocket.v1'
#: Subprotocols a client may offer, in the server's order of preference.
ACCEPTED = (SDK_SUBPROTOCOL, LEGACY_SUBPROTOCOL)
#: Longest HTTP upgrade request or answer [bytes], and the time a client has to send it [s].
MAX_HEADER = 65536
HANDSHAKE_TIMEOUT = 10.0
CHUNK = 262144
FAILURE = 'foxglove view (subprotocol proxy)'


def _read_header(sock: socket.socket) -> Tuple[bytes, bytes]:
    """Return (the HTTP header up to and including the blank line, the bytes after it)."""
    data = b''
    while b'\r\n\r\n' not in data:
        if len(data) > MAX_HEADER:
            raise ValueError(f'HTTP header longer than {MAX_HEADER} bytes')
        chunk = sock.recv(4096)
        if not chunk:
            raise ConnectionError('closed during the handshake')
        data += chunk
    end = data.index(b'\r\n\r\n') + 4
    return data[:end], data[end:]


def offered_subprotocols(header: bytes) -> List[str]:
    """The subprotocols a WebSocket upgrade request offers (``Sec-WebSocket-Protocol``)."""
    offered: List[str] = []
    for line in header.split(b'\r\n')[1:]:
        name, sep, value = line.partition(b':')
        if sep and name.strip().lower() == b'sec-websocket-protocol':
            offered += [p.strip() for p in value.decode('latin-1').split(',') if p.strip()]
    return offered


def _set_subprotocol(header: bytes, subprotocol: str) -> bytes:
    """Return ``header`` with its ``Sec-WebSocket-Protocol`` lines replaced by one naming
    ``subprotocol``."""
    lines = header[:-4].split(b'\r\n')
    kept = [line for line in lines
            if line.partition(b':')[0].strip().lower() != b'sec-websocket-protocol']
    kept.append(b'Sec-WebSocket-Protocol: ' + subprotocol.encode())
    return b'\r\n'.join(kept) + b'\r\n\r\n'


def refusal(offered: List[str]) -> bytes:
    """The HTTP 400 answer to a client that offers none of the accepted subprotocols."""
    body = (f'This is a Foxglove WebSocket server of conveyor_twin. It speaks the Foxglove '
            f'WebSocket protocol v1 under the subprotocol names {" or ".join(ACCEPTED)}; the '
            f'client offered {", ".join(offered) if offered else "none"}. Connect with '
            'Foxglove (Open connection, Foxglove WebSocket) or Lichtblick.\n').encode()
    return (b'HTTP/1.1 400 Bad Request\r\nContent-Type: text/plain; charset=utf-8\r\n'
            b'Connection: close\r\nContent-Length: ' + str(len(body)).encode()
            + b'\r\n\r\n' + body)


class SubprotocolProxy:
    """Accepts clients at ``host:port`` for the SDK server at 127.0.0.1:``inner_port``.

    :param health: where an unexpected exception of the proxy's threads is reported.
    :param on_refused: called with the offered subprotocols of each refused handshake.
    :raises OSError: if it cannot listen at ``host:port``.
    """

    def __init__(self, host: str, port: int, inner_port: int, *, health: Health,
                 on_refused: Optional[Callable[[List[str]], None]] = None) -> None:
        self.inner_port = inner_port
        self.health = health
        self.on_refused = on_refused or (lambda offered: None)
        self.refused = 0
        self.legacy = 0      # connections that offered only foxglove.websocket.v1
        family = socket.AF_INET6 if ':' in host else socket.AF_INET
        self._listener = socket.socket(family, socket.SOCK_STREAM)
        try:
            self._listener.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            self._listener.bind((host, port))
            self._listener.listen(64)
        except OSError:
            self._listener.close()
            raise
        self.port = self._listener.getsockname()[1]
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._sockets: List[socket.socket] = []
        self._accepting = health.thread(FAILURE, self._accept_loop)
        self._accepting.start()

    def stop(self) -> None:
        """Stop accepting and close every connection."""
        self._stop.set()
        try:
            self._listener.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self._listener.close()
        self._accepting.join(2.0)
        with self._lock:
            sockets, self._sockets = self._sockets, []
        for sock in sockets:
            _close(sock)

    def _accept_loop(self) -> None:
        while not self._stop.is_set():
            try:
                client, _ = self._listener.accept()
            except OSError:
                if self._stop.is_set():
                    return
                raise
            self.health.thread(FAILURE, self._serve, client).start()

    def _track(self, sock: socket.socket) -> None:
        with self._lock:
            self._sockets = [s for s in self._sockets if s.fileno() != -1] + [sock]

    def _serve(self, client: socket.socket) -> None:
        """Handshake of one client, then copy both ways until either side closes."""
        self._track(client)
        try:
            client.settimeout(HANDSHAKE_TIMEOUT)
            header, rest = _read_header(client)
            offered = offered_subprotocols(header)
            legacy = SDK_SUBPROTOCOL not in offered and LEGACY_SUBPROTOCOL in offered
            if not legacy and SDK_SUBPROTOCOL not in offered:
                self.refused += 1
                client.sendall(refusal(offered))
                _close(client)
                self.on_refused(offered)
                return None
            inner = socket.create_connection(('127.0.0.1', self.inner_port),
                                             timeout=HANDSHAKE_TIMEOUT)
            self._track(inner)
            if legacy:
                self.legacy += 1
                header = _set_subprotocol(header, SDK_SUBPROTOCOL)
            inner.sendall(header + rest)
            if legacy:
                answer, after = _read_header(inner)
                if offered_subprotocols(answer):
                    answer = _set_subprotocol(answer, LEGACY_SUBPROTOCOL)
                client.sendall(answer + after)
        except (OSError, ValueError):  # a client that went away or sent no HTTP: its own end
            _close(client)
            return None
        client.settimeout(None)
        inner.settimeout(None)
        for sock in (client, inner):
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.health.thread(FAILURE, _copy, inner, client).start()
        _copy(client, inner)


def _copy(source: socket.socket, target: socket.socket) -> None:
    """Copy ``source`` to ``target`` until either closes; then close both."""
    buffer = bytearray(CHUNK)
    view = memoryview(buffer)
    try:
        while True:
            n = source.recv_into(buffer)
            if not n:
                break
            target.sendall(view[:n])
    except OSError:
        pass
    finally:
        _close(source)
        _close(target)


def _close(sock: socket.socket) -> None:
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    sock.close()
