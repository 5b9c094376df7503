"""A plain WebSocket client of the Foxglove view that keeps every message it receives.

It speaks the Foxglove WebSocket protocol with the ``websockets`` package (as
``test/viz/test_foxglove.py`` does): it subscribes to every channel the server advertises and
collects the binary message data in a thread of its own, so the server's per-client backlog
never fills while a test steps the twin. ``foxglove.Grid`` frames (protobuf) are decoded with
the few lines of the protobuf wire format they need.
"""

import json
import struct
import threading
import time
from typing import Callable, Dict, List, NamedTuple, Optional, Tuple

import numpy as np

SUBPROTOCOL = 'foxglove.sdk.v1'
TIMEOUT = 60.0  # s: longest wait for the server


class Received(NamedTuple):
    """One message a client received: topic, log time [ns] and payload."""

    topic: str
    log_time: int
    data: bytes


class FoxgloveClient:
    """Connect to ``ws://127.0.0.1:PORT``, subscribe to every channel, collect messages.

    :param port: where the view listens.
    :param ready: the channels that must be advertised before subscribing (topic names).
    :param failed: while connecting, returns why the server is gone for good (None: not).
    """

    def __init__(self, port: int, ready: Tuple[str, ...] = ('/parts',),
                 failed: Callable[[], Optional[str]] = lambda: None) -> None:
        from websockets.sync.client import connect
        deadline = time.monotonic() + TIMEOUT
        while True:  # a server in another process may not listen yet
            try:
                self._connection = connect(f'ws://127.0.0.1:{port}',
                                           subprotocols=[SUBPROTOCOL], open_timeout=TIMEOUT)
                self.ws = self._connection.__enter__()
                break
            except ConnectionRefusedError:
                reason = failed()
                if reason is not None:
                    raise AssertionError(f'no Foxglove server at port {port}: {reason}') \
                        from None
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)
        self.channels: Dict[str, dict] = {}
        self.received: List[Received] = []
        self.statuses: List[dict] = []
        self.error: Optional[BaseException] = None
        self._subscribed: Dict[int, str] = {}
        self._stop = threading.Event()
        self._lock = threading.Lock()
        deadline = time.monotonic() + TIMEOUT
        while not set(ready) <= set(self.channels):
            self._take(self.ws.recv(timeout=max(0.01, deadline - time.monotonic())))
        self._subscribe_new()
        self._thread = threading.Thread(target=self._loop, name='foxglove_test_client',
                                        daemon=True)
        self._thread.start()

    def _take(self, message) -> None:
        if isinstance(message, bytes):
            if message[0] == 1:  # message data: opcode, subscription id, log time, payload
                subscription, log_time = struct.unpack_from('<IQ', message, 1)
                topic = self._subscribed.get(subscription, '')
                with self._lock:
                    self.received.append(Received(topic, log_time, bytes(message[13:])))
            return
        op = json.loads(message)
        if op['op'] == 'advertise':
            self.channels.update({c['topic']: c for c in op['channels']})
        elif op['op'] == 'status':
            self.statuses.append(op)

    def _subscribe_new(self) -> None:
        new = [c for c in self.channels.values()
               if c['topic'] not in self._subscribed.values()]
        if not new:
            return
        first = len(self._subscribed) + 1
        subscriptions = []
        for i, channel in enumerate(new, first):
            self._subscribed[i] = channel['topic']
            subscriptions.append({'id': i, 'channelId': channel['id']})
        self.ws.send(json.dumps({'op': 'subscribe', 'subscriptions': subscriptions}))

    def _loop(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    message = self.ws.recv(timeout=0.1)
                except TimeoutError:
                    continue
                self._take(message)
                self._subscribe_new()  # channels advertised later (e.g. a density grid)
        except BaseException as exc:  # noqa: BLE001 - reported by the test that waits
            if not self._stop.is_set():
                self.error = exc

    def messages(self, topic: str) -> List[Received]:
        """Return the messages received on ``topic`` so far, in order."""
        with self._lock:
            return [m for m in self.received if m.topic == topic]

    def wait(self, condition: Callable[[], bool], what: str, timeout: float = TIMEOUT) -> None:
        """Wait until ``condition()`` holds; fail naming ``what`` and what arrived."""
        deadline = time.monotonic() + timeout
        while not condition():
            if self.error is not None:
                raise AssertionError(f'{what}: the client failed: {self.error!r}')
            if time.monotonic() > deadline:
                with self._lock:
                    counts: Dict[str, int] = {}
                    for m in self.received:
                        counts[m.topic] = counts.get(m.topic, 0) + 1
                raise AssertionError(f'{what}: not within {timeout:g} s; received per topic '
                                     f'{counts}; statuses {self.statuses[-3:]}')
            time.sleep(0.02)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5.0)
        self._connection.__exit__(None, None, None)


# -- foxglove.Grid (protobuf) -------------------------------------------------------------------
def _varint(data: bytes, pos: int) -> Tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, pos


def _fields(data: bytes) -> Dict[int, list]:
    """Return the fields of a protobuf message: number -> values (ints or bytes)."""
    out: Dict[int, list] = {}
    pos = 0
    while pos < len(data):
        key, pos = _varint(data, pos)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, pos = _varint(data, pos)
        elif wire == 1:
            value, pos = data[pos:pos + 8], pos + 8
        elif wire == 2:
            length, pos = _varint(data, pos)
            value, pos = data[pos:pos + length], pos + length
        elif wire == 5:
            value, pos = data[pos:pos + 4], pos + 4
        else:
            raise ValueError(f'protobuf wire type {wire} of field {number} is not supported')
        out.setdefault(number, []).append(value)
    return out


class GridFrame(NamedTuple):
    """A decoded ``foxglove.Grid`` with one float32 field: stamp [ns] and the grid (ny, nx)."""

    stamp_ns: int
    frame_id: str
    origin: Tuple[float, float]
    resolution: float
    field_names: Tuple[str, ...]
    values: np.ndarray


def decode_grid(data: bytes) -> GridFrame:
    """Decode a ``foxglove.Grid`` protobuf message (fields as ``foxglove/Grid.proto``)."""
    f = _fields(data)
    stamp = _fields(f[1][0]) if 1 in f else {}
    stamp_ns = stamp.get(1, [0])[0] * 1_000_000_000 + stamp.get(2, [0])[0]
    pose = _fields(f[3][0]) if 3 in f else {}
    position = _fields(pose[1][0]) if 1 in pose else {}
    origin = tuple(struct.unpack('<d', position[k][0])[0] if k in position else 0.0
                   for k in (1, 2))
    cell_size = _fields(f[5][0]) if 5 in f else {}
    resolution = struct.unpack('<d', cell_size[1][0])[0] if 1 in cell_size else 0.0
    columns = struct.unpack('<I', f[4][0])[0]
    row_stride = struct.unpack('<I', f[6][0])[0]
    cell_stride = struct.unpack('<I', f[7][0])[0]
    names = tuple(_fields(field)[1][0].decode() for field in f.get(8, []))
    raw = f.get(9, [b''])[0]
    if cell_stride != 4 or row_stride != 4 * columns:
        raise ValueError(f'grid strides {cell_stride}/{row_stride} are not one float32 per cell')
    values = np.frombuffer(raw, '<f4').reshape(-1, columns) if columns else np.zeros((0, 0))
    return GridFrame(stamp_ns, f.get(2, [b''])[0].decode(), origin, resolution, names, values)
