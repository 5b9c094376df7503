"""CDR (XCDR1, little endian) basics: the encapsulation, times, alignment and the writers.

Every message starts with the 4-byte encapsulation header ``00 01 00 00`` (CDR little endian)
followed by the payload. Inside the payload, primitives are aligned to their size relative to
the payload start; a sequence is a ``uint32`` element count followed by the elements (aligned
to the element size only when the sequence is not empty, as Fast CDR does); a string is a
``uint32`` length that counts the terminating NUL, the UTF-8 bytes and the NUL. Padding bytes
are zero, so equal inputs give equal bytes (recordings stay bit-identical).

:class:`CdrBuilder` writes fixed parts and low-rate messages field by field;
:class:`CdrBuffer` is the reusable, 8-byte aligned buffer the hot encoders fill in place.
Times are integer nanoseconds of simulation time, split exactly into
``builtin_interfaces/Time`` (``sec``, ``nanosec``) without floating point.
"""

import struct
from typing import Any, Sequence, Tuple

import numpy as np

#: Encapsulation header of CDR little endian (XCDR1), as rmw_fastrtps writes it.
ENCAPSULATION_LE = b'\x00\x01\x00\x00'
NS_PER_S = 1_000_000_000
INT32_MAX = 2**31 - 1

#: ``builtin_interfaces/Time`` (sec, nanosec) and the primitives the encoders write.
STAMP = struct.Struct('<iI')
U32 = struct.Struct('<I')
U64 = struct.Struct('<Q')
F64 = struct.Struct('<d')


class CdrError(ValueError):
    """Raised for malformed CDR data or arguments that cannot be encoded."""


def stamp_of(data: bytes) -> int:
    """Return the stamp [ns] of little-endian CDR bytes whose first field is a
    ``builtin_interfaces/Time`` or a ``std_msgs/Header`` (every stamped stream of the twin)."""
    return (int.from_bytes(data[4:8], 'little') * NS_PER_S
            + int.from_bytes(data[8:12], 'little'))


def stamp_parts(stamp_ns: int) -> Tuple[int, int]:
    """Split a time into ``(sec, nanosec)`` of ``builtin_interfaces/Time``, exactly.

    :param stamp_ns: time [ns], 0 <= stamp_ns < 2**31 s.
    :raises CdrError: if the time does not fit ``int32`` seconds or is negative.
    """
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    if not 0 <= sec <= INT32_MAX:
        msg = f'stamp {stamp_ns} ns does not fit builtin_interfaces/Time (0 <= sec < 2**31)'
        raise CdrError(msg)
    return sec, nanosec


def align(pos: int, size: int) -> int:
    """Return ``pos`` [bytes] rounded up to a multiple of ``size`` (a power of two)."""
    return (pos + size - 1) & -size


def string_bytes(value: str) -> bytes:
    """Return the CDR string body (length incl. NUL, bytes, NUL); the caller aligns to 4.

    :raises CdrError: if the string contains a NUL character.
    """
    data = value.encode('utf-8')
    if b'\x00' in data:
        raise CdrError(f'string {value!r} contains a NUL character')
    return U32.pack(len(data) + 1) + data + b'\x00'


class CdrBuilder:
    """Slow, general CDR payload builder for fixed parts and low-rate messages."""

    def __init__(self) -> None:
        self.buf = bytearray()

    @property
    def pos(self) -> int:
        """Payload bytes written so far [bytes]."""
        return len(self.buf)

    def align(self, size: int) -> None:
        """Pad with zeros to a multiple of ``size`` [bytes]."""
        self.buf.extend(bytes(align(len(self.buf), size) - len(self.buf)))

    def stamp(self, stamp_ns: int) -> None:
        """Write a ``builtin_interfaces/Time`` of ``stamp_ns`` [ns]."""
        self.align(4)
        self.buf.extend(STAMP.pack(*stamp_parts(stamp_ns)))

    def string(self, value: str) -> None:
        """Write a string."""
        self.align(4)
        self.buf.extend(string_bytes(value))

    def strings(self, values: Sequence[str]) -> None:
        """Write a sequence of strings."""
        self.u32(len(values))
        for value in values:
            self.string(value)

    def u32(self, value: int) -> None:
        """Write a ``uint32``."""
        self.align(4)
        self.buf.extend(U32.pack(value))

    def u64(self, value: int) -> None:
        """Write a ``uint64``."""
        self.align(8)
        self.buf.extend(U64.pack(value))

    def f64(self, value: float) -> None:
        """Write a ``float64``."""
        self.align(8)
        self.buf.extend(F64.pack(value))

    def boolean(self, value: bool) -> None:
        """Write a ``bool`` (one byte, 0 or 1)."""
        self.buf.append(1 if value else 0)

    def message(self) -> bytes:
        """Return the encapsulation header followed by the payload written."""
        return ENCAPSULATION_LE + bytes(self.buf)


class CdrBuffer:
    """Reusable message buffer whose payload starts 8-byte aligned in memory.

    ``raw[4:8]`` holds the encapsulation header and ``raw[8:]`` the payload, so payload offset
    ``p`` is ``raw[8 + p]`` and numpy views of 8-byte elements are aligned.
    """

    def __init__(self, payload_size: int) -> None:
        """Allocate a zeroed buffer for ``payload_size`` payload bytes."""
        self.raw = np.zeros(payload_size + 16, dtype=np.uint8)
        self.raw[4:8] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)

    def view(self, pos: int, count: int, dtype: Any) -> np.ndarray:
        """Return a view of ``count`` elements of ``dtype`` at payload offset ``pos``."""
        size = np.dtype(dtype).itemsize * count
        return self.raw[8 + pos:8 + pos + size].view(dtype)

    def put(self, pos: int, data: bytes) -> None:
        """Copy ``data`` to payload offset ``pos``."""
        self.raw[8 + pos:8 + pos + len(data)] = np.frombuffer(data, dtype=np.uint8)

    def message(self, payload_size: int) -> bytes:
        """Return the encapsulation header and the first ``payload_size`` payload bytes."""
        return self.raw[4:8 + payload_size].tobytes()


def header_prefix(frame_id: str) -> bytes:
    """Return the payload of a std_msgs/Header with a zero stamp (stamp at payload 0..8)."""
    b = CdrBuilder()
    b.stamp(0)
    b.string(frame_id)
    return bytes(b.buf)
