"""A plain WebSocket client's side of the Foxglove protocol, for the view's tests.

Every receive has a time budget (:class:`Deadline`): a loop ends whatever the server does.
"""

import json
import struct
import time
from typing import Dict, Iterator, List, Tuple

SUBPROTOCOL = 'foxglove.sdk.v1'
TIMEOUT = 30.0  # s


class Deadline:
    """A time budget for a receive loop."""

    def __init__(self, seconds: float = TIMEOUT) -> None:
        self.end = time.monotonic() + seconds

    def left(self) -> float:
        left = self.end - time.monotonic()
        if left <= 0.0:
            raise AssertionError('the Foxglove server did not answer in time')
        return left


def advertised(ws, wanted: str = '/parts') -> dict:
    """Return topic -> channel of the server's advertisements, once ``wanted`` is among them."""
    channels: dict = {}
    deadline = Deadline()
    while wanted not in channels:
        message = ws.recv(timeout=deadline.left())
        if isinstance(message, str):
            data = json.loads(message)
            if data['op'] == 'advertise':
                channels.update({c['topic']: c for c in data['channels']})
    return channels


def subscribe(ws, channels: dict, topics) -> Dict[int, str]:
    """Subscribe to ``topics``; return subscription id -> topic."""
    ids = {i + 1: topic for i, topic in enumerate(topics)}
    ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
        {'id': i, 'channelId': channels[topic]['id']} for i, topic in ids.items()]}))
    return ids


def messages(ws, deadline: Deadline, texts: List[dict] = None) -> Iterator[Tuple[int, int,
                                                                                 bytes]]:
    """Yield (subscription id, log time [ns], payload) of the message data received; JSON
    messages go to ``texts`` if given."""
    while True:
        message = ws.recv(timeout=deadline.left())
        if isinstance(message, bytes) and message[0] == 1:
            subscription, log_time = struct.unpack_from('<IQ', message, 1)
            yield subscription, log_time, message[13:]
        elif isinstance(message, str) and texts is not None:
            texts.append(json.loads(message))


def protobuf_fields(data: bytes) -> Dict[int, list]:
    """Decode one level of a protobuf message: field number -> values (varints as int,
    fixed32/64 as raw 4/8 bytes, length-delimited as bytes)."""
    fields: Dict[int, list] = {}
    i = 0

    def varint() -> int:
        nonlocal i
        shift = value = 0
        while True:
            byte = data[i]
            i += 1
            value |= (byte & 0x7F) << shift
            shift += 7
            if not byte & 0x80:
                return value

    while i < len(data):
        key = varint()
        number, wire = key >> 3, key & 7
        if wire == 0:
            value = varint()
        elif wire == 1:
            value, i = data[i:i + 8], i + 8
        elif wire == 2:
            n = varint()
            value, i = data[i:i + n], i + n
        elif wire == 5:
            value, i = data[i:i + 4], i + 4
        else:
            raise ValueError(f'protobuf wire type {wire} at byte {i}')
        fields.setdefault(number, []).append(value)
    return fields


#: Field numbers of ``foxglove.Grid`` as foxglove-sdk encodes it (checked against the SDK's own
#: encoder in the tests).
GRID_FIELDS = {'frame_id': 2, 'column_count': 4, 'row_stride': 6, 'cell_stride': 7, 'data': 9}


def decode_grid(payload: bytes):
    """Return (frame_id, column_count, data bytes) of a protobuf ``foxglove.Grid``."""
    fields = protobuf_fields(payload)
    frame_id = fields[GRID_FIELDS['frame_id']][0].decode()
    columns, = struct.unpack('<I', fields[GRID_FIELDS['column_count']][0])
    return frame_id, columns, fields[GRID_FIELDS['data']][0]
