"""The view's front door: both subprotocol names of the Foxglove protocol v1 reach the SDK's
server as the one it accepts; anything else gets a plain HTTP 400; bytes pass unchanged."""

import socket
import threading

from conveyor_twin.health import Health
from conveyor_twin.viz.foxglove_proxy import (SubprotocolProxy, _read_header,
                                              _set_subprotocol, offered_subprotocols)

UPGRADE = (b'GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n'
           b'Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n')


def _request(*subprotocols: str) -> bytes:
    lines = b''.join(b'Sec-WebSocket-Protocol: ' + p.encode() + b'\r\n' for p in subprotocols)
    return UPGRADE + lines + b'\r\n'


class _Inner:
    """A stand-in for the SDK's server: answers the handshake naming the subprotocol it was
    asked for, then echoes; records the request it got."""

    def __init__(self) -> None:
        self.sock = socket.socket()
        self.sock.bind(('127.0.0.1', 0))
        self.sock.listen(4)
        self.port = self.sock.getsockname()[1]
        self.requests = []
        threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        conn, _ = self.sock.accept()
        header, rest = _read_header(conn)
        self.requests.append(header)
        offered = offered_subprotocols(header)
        conn.sendall(b'HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\n'
                     b'Sec-WebSocket-Protocol: ' + offered[0].encode() + b'\r\n\r\n' + rest)
        while True:
            data = conn.recv(65536)
            if not data:
                break
            conn.sendall(data)
        conn.close()


def _exchange(proxy: SubprotocolProxy, request: bytes, payload: bytes) -> bytes:
    with socket.create_connection(('127.0.0.1', proxy.port), timeout=30.0) as client:
        client.sendall(request)
        header, rest = _read_header(client)
        client.sendall(payload)
        data = rest
        while len(data) < len(payload):
            chunk = client.recv(65536)
            assert chunk, 'the proxy closed the connection'
            data += chunk
        return header + data


def test_headers_are_read_and_rewritten():
    request = _request('foxglove.websocket.v1, other') + b''
    assert offered_subprotocols(request) == ['foxglove.websocket.v1', 'other']
    rewritten = _set_subprotocol(request, 'foxglove.sdk.v1')
    assert offered_subprotocols(rewritten) == ['foxglove.sdk.v1']
    assert rewritten.endswith(b'\r\n\r\n') and b'Sec-WebSocket-Key' in rewritten


def test_the_former_name_is_forwarded_as_the_sdk_name_and_answered_as_asked():
    inner, health = _Inner(), Health(printer=lambda text: None)
    proxy = SubprotocolProxy('127.0.0.1', 0, inner.port, health=health)
    try:
        payload = bytes(range(256)) * 1000
        answer = _exchange(proxy, _request('foxglove.websocket.v1'), payload)
        header, _, data = answer.partition(b'\r\n\r\n')
        assert offered_subprotocols(header + b'\r\n\r\n') == ['foxglove.websocket.v1']
        assert offered_subprotocols(inner.requests[0]) == ['foxglove.sdk.v1']
        assert data == payload and proxy.legacy == 1
    finally:
        proxy.stop()
    assert health.ok, health.failures


def test_the_sdk_name_goes_through_unchanged():
    inner, health = _Inner(), Health(printer=lambda text: None)
    proxy = SubprotocolProxy('127.0.0.1', 0, inner.port, health=health)
    try:
        request = _request('foxglove.sdk.v1')
        answer = _exchange(proxy, request, b'x' * 10)
        assert inner.requests[0] == request and answer.endswith(b'x' * 10)
        assert proxy.legacy == 0
    finally:
        proxy.stop()


def test_anything_else_gets_a_plain_400_and_a_silent_client_costs_nothing():
    inner, health = _Inner(), Health(printer=lambda text: None)
    proxy = SubprotocolProxy('127.0.0.1', 0, inner.port, health=health)
    try:
        for request, offered in ((b'GET / HTTP/1.1\r\nHost: x\r\n\r\n', 'none'),
                                 (_request('json.v2'), 'json.v2')):
            with socket.create_connection(('127.0.0.1', proxy.port), timeout=30.0) as client:
                client.sendall(request)
                answer = b''
                while True:
                    chunk = client.recv(65536)
                    if not chunk:
                        break
                    answer += chunk
            assert answer.startswith(b'HTTP/1.1 400 Bad Request')
            text = answer.decode()
            assert 'foxglove.sdk.v1 or foxglove.websocket.v1' in text
            assert f'offered {offered}' in text
        socket.create_connection(('127.0.0.1', proxy.port), timeout=30.0).close()
        assert proxy.refused == 2 and inner.requests == []
    finally:
        proxy.stop()
    assert health.ok, health.failures
