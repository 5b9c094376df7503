"""CDR of ``diagnostic_msgs/DiagnosticArray``, written straight from strings.

The twin's diagnostics are built on the stepping thread once a second; rclpy message objects
(one per status and per key-value pair, each field checked on assignment) and
``serialize_message`` cost about 0.5 ms there with cold caches, half the step's budget. This
writes the same bytes as rmw_fastrtps (``serialize_message``) in a few tens of microseconds.

A status is a :class:`Status` or anything with the same attributes (a
``diagnostic_msgs/DiagnosticStatus`` message object, whose ``values`` hold ``KeyValue``
objects); the values of a :class:`Status` are ``(key, value)`` pairs. The decoder is
:func:`conveyor_twin.wire.decoders.decode_diagnostic_array`.
"""

import struct
from typing import Any, Dict, List, NamedTuple, Sequence, Tuple, Union

from conveyor_twin.wire.builder import CdrError, ENCAPSULATION_LE, stamp_parts

# diagnostic_msgs/DiagnosticStatus levels [byte]
OK, WARN, ERROR, STALE = 0, 1, 2, 3

_STAMP = struct.Struct('<iI')
_U32 = struct.Struct('<I')
_ZEROS = (b'', b'\x00', b'\x00\x00', b'\x00\x00\x00')  # padding of 0-3 bytes
_LEVELS = tuple(bytes([i]) for i in range(256))


class Status(NamedTuple):
    """One ``DiagnosticStatus``: level (:data:`OK` ... :data:`STALE`), name, message,
    hardware id and ``(key, value)`` string pairs."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: Sequence[Tuple[str, str]]


#: string -> its CDR body (length with the NUL, UTF-8 bytes, NUL) padded to a multiple of 4,
#: and the body's length without the padding (keys and most values repeat every message)
_BODIES: Dict[str, Tuple[bytes, int]] = {}
_BODIES_MAX = 4096


def _body(value: str) -> Tuple[bytes, int]:
    """Return the padded CDR body of a string and its unpadded length."""
    entry = _BODIES.get(value)
    if entry is None:
        data = value.encode('utf-8')
        if b'\x00' in data:
            raise CdrError(f'string {value!r} contains a NUL character')
        body = _U32.pack(len(data) + 1) + data + b'\x00'
        entry = (body + _ZEROS[-len(body) & 3], len(body))
        if len(_BODIES) >= _BODIES_MAX:
            _BODIES.clear()
        _BODIES[value] = entry
    return entry


def _level(level: Union[int, bytes]) -> int:
    """Return a status level as an int (rclpy's message objects hold it as one byte)."""
    value = level[0] if isinstance(level, (bytes, bytearray)) else int(level)
    if not 0 <= value <= 255:
        raise CdrError(f'diagnostic level {value}: expected 0..255')
    return value


def _pairs(values: Sequence[Any]) -> List[Tuple[str, str]]:
    """Return ``(key, value)`` pairs of tuples or ``KeyValue`` message objects."""
    return [v if isinstance(v, tuple) else (v.key, v.value) for v in values]


def encode_diagnostic_array(stamp_ns: int, frame_id: str, statuses: Sequence[Any]) -> bytes:
    """Return the CDR bytes of a DiagnosticArray message.

    :param stamp_ns: ``header.stamp``, simulation time [ns].
    :param frame_id: ``header.frame_id``.
    :param statuses: :class:`Status` tuples or ``DiagnosticStatus`` message objects.
    :raises CdrError: on a string with a NUL, a level beyond a byte or a stamp out of range.
    """
    # Every string starts 4-aligned (it follows a string, a count or a level byte plus its
    # padding), so each is written with the padding that aligns what follows, except the last
    # one of a status: the next status's level byte is not aligned (nor is the message's end).
    frame, _ = _body(frame_id)
    out = [ENCAPSULATION_LE, _STAMP.pack(*stamp_parts(stamp_ns)), frame,
           _U32.pack(len(statuses))]
    pos = 12 + len(frame)  # payload bytes so far
    for status in statuses:
        pad = -(pos + 1) & 3
        pairs = _pairs(status.values)
        chunk = [_LEVELS[_level(status.level)], _ZEROS[pad], _body(status.name)[0],
                 _body(status.message)[0], _body(status.hardware_id)[0], _U32.pack(len(pairs))]
        for key, value in pairs:
            chunk.append(_body(key)[0])
            chunk.append(_body(value)[0])
        if pairs:  # the last string without the padding after it
            chunk[-1] = chunk[-1][:_body(pairs[-1][1])[1]]
        data = b''.join(chunk)
        out.append(data)
        pos += len(data)
    return b''.join(out)
