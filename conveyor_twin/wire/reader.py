"""Bounds-checked CDR payload reader (XCDR1, little or big endian) for the decoders."""

import struct
from typing import Any

import numpy as np

from conveyor_twin.wire.builder import align, CdrError, NS_PER_S


class CdrReader:
    """Read the fields of one CDR message in order; every read checks the bounds."""

    def __init__(self, data: bytes, type_name: str) -> None:
        """Start reading after the encapsulation header.

        :param data: CDR bytes including the 4-byte encapsulation header.
        :param type_name: type named in the errors (e.g. ``PartStates``).
        :raises CdrError: on data shorter than the header or an unsupported encapsulation.
        """
        self.type_name = type_name
        if len(data) < 4:
            raise CdrError(f'{type_name}: {len(data)} bytes are too short for CDR')
        kind = bytes(data[:2])
        if kind == b'\x00\x01':
            self.order = '<'
        elif kind == b'\x00\x00':
            self.order = '>'
        else:
            raise CdrError(f'{type_name}: unsupported encapsulation {kind.hex()}')
        self.data = memoryview(data)[4:]
        self.pos = 0

    def _take(self, size: int, alignment: int) -> int:
        start = align(self.pos, alignment)
        if start + size > len(self.data):
            msg = (f'{self.type_name}: truncated, {size} bytes needed at payload offset '
                   f'{start} of {len(self.data)}')
            raise CdrError(msg)
        self.pos = start + size
        return start

    def at_end(self) -> bool:
        """True when no field follows (at most the padding of the last one)."""
        return len(self.data) - self.pos < 4

    def scalar(self, fmt: str) -> Any:
        """Read one primitive of ``struct`` format ``fmt`` (``'I'``, ``'Q'``, ``'d'``, ...)."""
        size = struct.calcsize(fmt)
        start = self._take(size, size)
        return struct.unpack_from(self.order + fmt, self.data, start)[0]

    def stamp_ns(self) -> int:
        """Read a ``builtin_interfaces/Time`` and return it in [ns]."""
        sec = self.scalar('i')
        nanosec = self.scalar('I')
        return sec * NS_PER_S + nanosec

    def string(self) -> str:
        """Read a string.

        :raises CdrError: on a string without its NUL or not UTF-8.
        """
        length = self.scalar('I')
        if length == 0:  # tolerated (some writers encode '' this way)
            return ''
        start = self._take(length, 1)
        raw = bytes(self.data[start:start + length])
        if raw[-1] != 0:
            raise CdrError(f'{self.type_name}: string at payload offset {start} lacks its NUL')
        try:
            return raw[:-1].decode('utf-8')
        except UnicodeDecodeError as err:
            raise CdrError(f'{self.type_name}: string is not UTF-8: {err}') from None

    def array(self, dtype: str) -> np.ndarray:
        """Read a sequence of a numpy ``dtype`` (``'u4'``, ``'f8'``, ...) into a new array."""
        count = self.scalar('I')
        item = np.dtype(dtype).itemsize
        if count == 0:
            return np.zeros(0, dtype=dtype)
        if count * item > len(self.data):
            raise CdrError(f'{self.type_name}: sequence length {count} exceeds the data')
        start = self._take(count * item, item)
        values = np.frombuffer(self.data, dtype=np.dtype(dtype).newbyteorder(self.order),
                               count=count, offset=start)
        return values.astype(dtype)
