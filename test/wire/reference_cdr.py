"""Slow, readable reference CDR serializer driven by the ros2msg texts (for the tests).

It walks the parsed fields of a type and writes every value one by one, so it shares no code
path with the template encoders of :mod:`conveyor_twin.wire.cdr` except the schema parser.
"""

import struct
from typing import Any, Dict, List

from conveyor_twin.wire.schemas import MSG_TEXTS, parse_fields, PRIMITIVES

_FORMATS = {
    'bool': '?', 'byte': 'B', 'char': 'B', 'int8': 'b', 'uint8': 'B', 'int16': 'h',
    'uint16': 'H', 'int32': 'i', 'uint32': 'I', 'int64': 'q', 'uint64': 'Q', 'float32': 'f',
    'float64': 'd',
}


class ReferenceWriter:
    """Serialize nested dicts to CDR little endian; record where padding was inserted."""

    def __init__(self) -> None:
        self.out = bytearray()
        self.padding: List[int] = []

    def align(self, size: int) -> None:
        while len(self.out) % size:
            self.padding.append(len(self.out) + 4)  # positions in the full message
            self.out.append(0)

    def primitive(self, base: str, value: Any) -> None:
        if base == 'string':
            data = value.encode('utf-8') + b'\x00'
            self.align(4)
            self.out += struct.pack('<I', len(data)) + data
            return
        fmt = _FORMATS[base]
        self.align(struct.calcsize(fmt))
        self.out += struct.pack('<' + fmt, value)

    def message(self, type_name: str, value: Dict[str, Any]) -> None:
        for field in parse_fields(type_name, MSG_TEXTS[type_name]):
            item = value[field.name]
            if field.array == 'unbounded':
                self.align(4)
                self.out += struct.pack('<I', len(item))
                for element in item:
                    self.value(field.base, element)
            else:
                self.value(field.base, item)

    def value(self, base: str, item: Any) -> None:
        if base in PRIMITIVES:
            self.primitive(base, item)
        else:
            self.message(base, item)


def serialize(type_name: str, value: Dict[str, Any]):
    """Return ``(cdr_bytes, padding_positions)`` of a message given as nested dicts."""
    writer = ReferenceWriter()
    writer.message(type_name, value)
    return b'\x00\x01\x00\x00' + bytes(writer.out), writer.padding


def header(stamp_ns: int, frame_id: str) -> Dict[str, Any]:
    """Return a std_msgs/Header dict."""
    return {'stamp': {'sec': stamp_ns // 10**9, 'nanosec': stamp_ns % 10**9},
            'frame_id': frame_id}
