"""CDR (XCDR1, little endian) encoders and decoders of the contract messages, straight from numpy.

Every encoder returns the complete serialized message as rmw_fastrtps produces it: the 4-byte
encapsulation header ``00 01 00 00`` (CDR little endian) followed by the payload. Inside the
payload, primitives are aligned to their size relative to the payload start; a sequence is a
``uint32`` element count followed by the elements (aligned to the element size only when the
sequence is not empty, as Fast CDR does); a string is a ``uint32`` length that counts the
terminating NUL, the UTF-8 bytes and the NUL. Padding bytes are zero, so equal inputs give
equal bytes (recordings stay bit-identical).

The hot streams (``parts``, ``density``, ``light_barriers``, ``belt_states``,
``actuator_states``) have encoder classes that precompute the fixed parts once per stream
(frame id, names, grid geometry) and fill a reusable, 8-byte aligned numpy buffer; each call
returns an immutable ``bytes`` copy, which can be handed to ``Publisher.publish`` and to the
recorder at the same time. Encoder instances are not thread-safe; the module-level
``encode_*`` functions keep one cached encoder per thread and per fixed part.

Times are integer nanoseconds of simulation time (``stamp_ns``), split exactly into
``builtin_interfaces/Time`` (``sec``, ``nanosec``) without floating point.
"""

import struct
import threading
from typing import Any, Dict, Hashable, NamedTuple, Sequence, Tuple

import numpy as np

#: Encapsulation header of CDR little endian (XCDR1), as rmw_fastrtps writes it.
ENCAPSULATION_LE = b'\x00\x01\x00\x00'
NS_PER_S = 1_000_000_000
_INT32_MAX = 2**31 - 1

_STAMP = struct.Struct('<iI')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')
_F64 = struct.Struct('<d')


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
    if not 0 <= sec <= _INT32_MAX:
        msg = f'stamp {stamp_ns} ns does not fit builtin_interfaces/Time (0 <= sec < 2**31)'
        raise CdrError(msg)
    return sec, nanosec


def _align(pos: int, size: int) -> int:
    return (pos + size - 1) & -size


def _string_bytes(value: str) -> bytes:
    """Return the CDR string body (length incl. NUL, bytes, NUL); the caller aligns to 4."""
    data = value.encode('utf-8')
    if b'\x00' in data:
        raise CdrError(f'string {value!r} contains a NUL character')
    return _U32.pack(len(data) + 1) + data + b'\x00'


class _Builder:
    """Slow, general CDR payload builder for fixed parts and low-rate messages."""

    def __init__(self) -> None:
        self.buf = bytearray()

    @property
    def pos(self) -> int:
        return len(self.buf)

    def align(self, size: int) -> None:
        self.buf.extend(bytes(_align(len(self.buf), size) - len(self.buf)))

    def stamp(self, stamp_ns: int) -> None:
        self.align(4)
        self.buf.extend(_STAMP.pack(*stamp_parts(stamp_ns)))

    def string(self, value: str) -> None:
        self.align(4)
        self.buf.extend(_string_bytes(value))

    def strings(self, values: Sequence[str]) -> None:
        self.u32(len(values))
        for value in values:
            self.string(value)

    def u32(self, value: int) -> None:
        self.align(4)
        self.buf.extend(_U32.pack(value))

    def u64(self, value: int) -> None:
        self.align(8)
        self.buf.extend(_U64.pack(value))

    def f64(self, value: float) -> None:
        self.align(8)
        self.buf.extend(_F64.pack(value))

    def boolean(self, value: bool) -> None:
        self.buf.append(1 if value else 0)

    def message(self) -> bytes:
        return ENCAPSULATION_LE + bytes(self.buf)


class _Buffer:
    """Reusable message buffer whose payload starts 8-byte aligned in memory.

    ``raw[4:8]`` holds the encapsulation header and ``raw[8:]`` the payload, so payload offset
    ``p`` is ``raw[8 + p]`` and numpy views of 8-byte elements are aligned.
    """

    def __init__(self, payload_size: int) -> None:
        self.raw = np.zeros(payload_size + 16, dtype=np.uint8)
        self.raw[4:8] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)

    def view(self, pos: int, count: int, dtype: Any) -> np.ndarray:
        """Return a view of ``count`` elements of ``dtype`` at payload offset ``pos``."""
        size = np.dtype(dtype).itemsize * count
        return self.raw[8 + pos:8 + pos + size].view(dtype)

    def put(self, pos: int, data: bytes) -> None:
        self.raw[8 + pos:8 + pos + len(data)] = np.frombuffer(data, dtype=np.uint8)

    def message(self, payload_size: int) -> bytes:
        return self.raw[4:8 + payload_size].tobytes()


def _header_prefix(frame_id: str) -> bytes:
    """Return the payload of a std_msgs/Header with a zero stamp (stamp at payload 0..8)."""
    b = _Builder()
    b.stamp(0)
    b.string(frame_id)
    return bytes(b.buf)


_F64_FIELDS = ('x', 'y', 'yaw', 'vx', 'vy', 'wz')


class PartStatesEncoder:
    """Encoder of ``conveyor_twin_msgs/PartStates`` for one stream (fixed frame id)."""

    def __init__(self, frame_id: str = 'cell', capacity: int = 1024) -> None:
        """Create the encoder.

        :param frame_id: ``header.frame_id`` of every message.
        :param capacity: number of parts the buffer is sized for at first (it grows).
        """
        self.frame_id = frame_id
        self._head = _header_prefix(frame_id)
        self._p_step = _align(len(self._head), 8)
        self._capacity = -1
        self._n = -1
        self._reserve(capacity)

    def _reserve(self, n: int) -> None:
        if n > self._capacity:
            self._capacity = max(n, 2 * self._capacity)
            self._buf = _Buffer(self._p_step + 64 + 54 * self._capacity)
            self._n = -1

    def _layout(self, n: int) -> None:
        """Set the layout (offsets, lengths, views) for ``n`` parts; zero all padding."""
        self._reserve(n)
        buf = self._buf
        buf.raw[:] = 0
        buf.raw[4:8] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
        buf.put(0, self._head)
        p = self._p_step + 8
        buf.put(p, _U32.pack(n))
        self._v_id = buf.view(p + 4, n, '<u4')
        p += 4 + 4 * n
        p = _align(p, 4)
        buf.put(p, _U32.pack(n))
        self._v_type = buf.view(p + 4, n, '<u2')
        p += 4 + 2 * n
        views = []
        for _ in _F64_FIELDS:
            p = _align(p, 4)
            buf.put(p, _U32.pack(n))
            p += 4
            if n:
                p = _align(p, 8)
            views.append(buf.view(p, n, '<f8'))
            p += 8 * n
        self._v_f64 = views
        self._size = p
        self._n = n

    def encode(self, stamp_ns: int, step: int, id: Any, part_type: Any, x: Any, y: Any,
               yaw: Any, vx: Any, vy: Any, wz: Any) -> bytes:
        """Return the CDR bytes of one PartStates message.

        :param stamp_ns: ``header.stamp``, simulation time [ns].
        :param step: simulation step index [1].
        :param id: part ids (uint32), one per part.
        :param part_type: part type indices (uint16).
        :param x: positions x [m]; ``y`` [m], ``yaw`` [rad], ``vx``, ``vy`` [m/s],
            ``wz`` [rad/s] alike, all of the same length.
        :raises CdrError: on arrays of unequal length or a stamp out of range.
        """
        n = len(id)
        arrays = (x, y, yaw, vx, vy, wz)
        if len(part_type) != n or any(len(a) != n for a in arrays):
            lengths = [len(a) for a in (id, part_type) + arrays]
            raise CdrError(f'PartStates arrays differ in length: {lengths}')
        if n != self._n:
            self._layout(n)
        raw = self._buf.raw
        _STAMP.pack_into(raw, 8, *stamp_parts(stamp_ns))
        _U64.pack_into(raw, 8 + self._p_step, step)
        self._v_id[...] = id
        self._v_type[...] = part_type
        for view, values in zip(self._v_f64, arrays):
            view[...] = values
        return self._buf.message(self._size)


class DensityGridEncoder:
    """Encoder of ``conveyor_twin_msgs/DensityGrid`` for one macro zone (fixed geometry)."""

    def __init__(self, frame_id: str, zone: str, origin_x: float, origin_y: float,
                 resolution: float, nx: int, ny: int) -> None:
        """Create the encoder for a zone's grid.

        :param frame_id: ``header.frame_id``.
        :param zone: zone name.
        :param origin_x: cell-frame x of the grid corner (ix=0, iy=0) [m].
        :param origin_y: cell-frame y of that corner [m].
        :param resolution: edge length of the square cells [m].
        :param nx: cells along x [1].
        :param ny: cells along y [1].
        """
        b = _Builder()
        b.buf.extend(_header_prefix(frame_id))
        self._p_step = _align(b.pos, 8)
        b.u64(0)
        b.string(zone)
        b.f64(origin_x)
        b.f64(origin_y)
        b.f64(resolution)
        b.u32(nx)
        b.u32(ny)
        self.count = nx * ny
        b.u32(self.count)
        p_density = b.pos
        b.buf.extend(bytes(4 * self.count))
        self._p_total = _align(b.pos, 8)
        b.f64(0.0)
        self._size = b.pos
        self._buf = _Buffer(self._size)
        self._buf.put(0, bytes(b.buf))
        self._v_density = self._buf.view(p_density, self.count, '<f4')

    def encode(self, stamp_ns: int, step: int, density: Any, total_parts: float) -> bytes:
        """Return the CDR bytes of one DensityGrid message.

        :param stamp_ns: ``header.stamp``, simulation time [ns].
        :param step: simulation step index [1].
        :param density: areal density [parts/m^2], ``nx*ny`` values row-major (index
            ``iy*nx+ix``), any shape with that many elements; stored as float32.
        :param total_parts: integral of the density over the grid [parts].
        :raises CdrError: on a density of the wrong size.
        """
        flat = np.ravel(density)
        if flat.size != self.count:
            raise CdrError(f'density has {flat.size} values, the grid {self.count}')
        raw = self._buf.raw
        _STAMP.pack_into(raw, 8, *stamp_parts(stamp_ns))
        _U64.pack_into(raw, 8 + self._p_step, step)
        self._v_density[...] = flat
        _F64.pack_into(raw, 8 + self._p_total, total_parts)
        return self._buf.message(self._size)


class LightBarrierStatesEncoder:
    """Encoder of ``conveyor_twin_msgs/LightBarrierStates`` (fixed frame id and names)."""

    def __init__(self, frame_id: str, names: Sequence[str]) -> None:
        """Create the encoder; the encoded names are computed once.

        :param frame_id: ``header.frame_id``.
        :param names: light barrier names, in the order of every message's arrays.
        """
        self.names = tuple(names)
        n = self.count = len(self.names)
        b = _Builder()
        b.buf.extend(_header_prefix(frame_id))
        self._p_step = _align(b.pos, 8)
        b.u64(0)
        b.strings(self.names)
        b.u32(n)
        p_blocked = b.pos
        b.buf.extend(bytes(n))
        b.u32(n)
        p_count = b.pos
        b.buf.extend(bytes(4 * n))
        self._size = b.pos
        self._buf = _Buffer(self._size)
        self._buf.put(0, bytes(b.buf))
        self._v_blocked = self._buf.view(p_blocked, n, np.uint8)
        self._v_count = self._buf.view(p_count, n, '<u4')

    def encode(self, stamp_ns: int, step: int, blocked: Any, edge_count: Any) -> bytes:
        """Return the CDR bytes of one LightBarrierStates message.

        :param stamp_ns: ``header.stamp``, simulation time [ns].
        :param step: simulation step index [1].
        :param blocked: true while a beam is interrupted, one per name.
        :param edge_count: edges since the last reset (uint32), one per name.
        :raises CdrError: on arrays whose length differs from the names.
        """
        if len(blocked) != self.count or len(edge_count) != self.count:
            msg = (f'LightBarrierStates: {len(blocked)} blocked and {len(edge_count)} '
                   f'edge counts for {self.count} names')
            raise CdrError(msg)
        raw = self._buf.raw
        _STAMP.pack_into(raw, 8, *stamp_parts(stamp_ns))
        _U64.pack_into(raw, 8 + self._p_step, step)
        np.not_equal(blocked, 0, out=self._v_blocked, casting='unsafe')
        self._v_count[...] = edge_count
        return self._buf.message(self._size)


class _NamedPairEncoder:
    """Encoder of a message ``header, string[] name, float64[] a, float64[] b``."""

    def __init__(self, frame_id: str, names: Sequence[str]) -> None:
        self.names = tuple(names)
        n = self.count = len(self.names)
        b = _Builder()
        b.buf.extend(_header_prefix(frame_id))
        b.strings(self.names)
        views = []
        for _ in range(2):
            b.u32(n)
            if n:
                b.align(8)
            views.append(b.pos)
            b.buf.extend(bytes(8 * n))
        self._size = b.pos
        self._buf = _Buffer(self._size)
        self._buf.put(0, bytes(b.buf))
        self._v_a = self._buf.view(views[0], n, '<f8')
        self._v_b = self._buf.view(views[1], n, '<f8')

    def encode(self, stamp_ns: int, commanded: Any, actual: Any) -> bytes:
        """Return the CDR bytes of one message.

        :param stamp_ns: ``header.stamp``, simulation time [ns].
        :param commanded: last accepted targets, one per name.
        :param actual: actual values, one per name.
        :raises CdrError: on arrays whose length differs from the names.
        """
        if len(commanded) != self.count or len(actual) != self.count:
            msg = (f'{type(self).__name__}: {len(commanded)} commanded and {len(actual)} '
                   f'actual values for {self.count} names')
            raise CdrError(msg)
        _STAMP.pack_into(self._buf.raw, 8, *stamp_parts(stamp_ns))
        self._v_a[...] = commanded
        self._v_b[...] = actual
        return self._buf.message(self._size)


class BeltStatesEncoder(_NamedPairEncoder):
    """Encoder of ``conveyor_twin_msgs/BeltStates``: speeds [m/s] of fixed belt names."""


class ActuatorStatesEncoder(_NamedPairEncoder):
    """Encoder of ``conveyor_twin_msgs/ActuatorStates``: positions [m or rad] of fixed names."""


_local = threading.local()


def _cached(cls: Any, key: Hashable, *args: Any) -> Any:
    cache: Dict[Any, Any] = getattr(_local, 'cache', None)
    if cache is None:
        cache = _local.cache = {}
    encoder = cache.get((cls, key))
    if encoder is None:
        if len(cache) > 256:
            cache.clear()
        encoder = cache[(cls, key)] = cls(*args)
    return encoder


def encode_part_states(stamp_ns: int, frame_id: str, step: int, id: Any, part_type: Any,
                       x: Any, y: Any, yaw: Any, vx: Any, vy: Any, wz: Any) -> bytes:
    """Return the CDR bytes of a PartStates message (see :meth:`PartStatesEncoder.encode`).

    :param frame_id: ``header.frame_id``.
    """
    encoder = _cached(PartStatesEncoder, frame_id, frame_id)
    return encoder.encode(stamp_ns, step, id, part_type, x, y, yaw, vx, vy, wz)


def encode_density_grid(stamp_ns: int, frame_id: str, step: int, zone: str, origin_x: float,
                        origin_y: float, resolution: float, nx: int, ny: int, density: Any,
                        total_parts: float) -> bytes:
    """Return the CDR bytes of a DensityGrid message (see :class:`DensityGridEncoder`)."""
    geometry = (frame_id, zone, float(origin_x), float(origin_y), float(resolution), int(nx),
                int(ny))
    encoder = _cached(DensityGridEncoder, geometry, *geometry)
    return encoder.encode(stamp_ns, step, density, total_parts)


def encode_light_barrier_states(stamp_ns: int, frame_id: str, step: int, names: Sequence[str],
                                blocked: Any, edge_count: Any) -> bytes:
    """Return the CDR bytes of a LightBarrierStates message (names encoded once per set)."""
    names = tuple(names)
    encoder = _cached(LightBarrierStatesEncoder, (frame_id, names), frame_id, names)
    return encoder.encode(stamp_ns, step, blocked, edge_count)


def encode_belt_states(stamp_ns: int, frame_id: str, names: Sequence[str],
                       commanded_speed: Any, speed: Any) -> bytes:
    """Return the CDR bytes of a BeltStates message; speeds [m/s]."""
    names = tuple(names)
    encoder = _cached(BeltStatesEncoder, (frame_id, names), frame_id, names)
    return encoder.encode(stamp_ns, commanded_speed, speed)


def encode_actuator_states(stamp_ns: int, frame_id: str, names: Sequence[str],
                           commanded_position: Any, position: Any) -> bytes:
    """Return the CDR bytes of an ActuatorStates message; positions [m] or [rad]."""
    names = tuple(names)
    encoder = _cached(ActuatorStatesEncoder, (frame_id, names), frame_id, names)
    return encoder.encode(stamp_ns, commanded_position, position)


def encode_light_barrier_edge(stamp_ns: int, frame_id: str, name: str, blocked: bool,
                              part_id: int) -> bytes:
    """Return the CDR bytes of a LightBarrierEdge message.

    :param stamp_ns: interpolated simulation time of the edge [ns].
    :param frame_id: ``header.frame_id``.
    :param name: light barrier name.
    :param blocked: true if the beam became interrupted.
    :param part_id: id of the micro part causing the edge, 0 for the macro scale.
    """
    b = _Builder()
    b.stamp(stamp_ns)
    b.string(frame_id)
    b.string(name)
    b.boolean(blocked)
    b.u32(part_id)
    return b.message()


def encode_clock(stamp_ns: int) -> bytes:
    """Return the CDR bytes of a rosgraph_msgs/Clock message.

    :param stamp_ns: simulation time [ns].
    """
    return ENCAPSULATION_LE + _STAMP.pack(*stamp_parts(stamp_ns))


def encode_belt_command(belt: str, speed: float, sender: str = '', sequence: int = 0) -> bytes:
    """Return the CDR bytes of a BeltCommand message; ``speed`` [m/s]; ``sender`` and
    ``sequence`` identify the command on ``command_status``."""
    return _encode_command(belt, speed, sender, sequence)


def encode_actuator_command(actuator: str, position: float, sender: str = '',
                            sequence: int = 0) -> bytes:
    """Return the CDR bytes of an ActuatorCommand message; ``position`` [m] or [rad];
    ``sender`` and ``sequence`` identify the command on ``command_status``."""
    return _encode_command(actuator, position, sender, sequence)


def _encode_command(name: str, value: float, sender: str, sequence: int) -> bytes:
    b = _Builder()
    b.string(name)
    b.f64(value)
    b.string(sender)
    b.u32(sequence)
    return b.message()


class _Reader:
    """Bounds-checked CDR payload reader (little or big endian)."""

    def __init__(self, data: bytes, type_name: str) -> None:
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

    def _take(self, size: int, align: int) -> int:
        start = _align(self.pos, align)
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
        size = struct.calcsize(fmt)
        start = self._take(size, size)
        return struct.unpack_from(self.order + fmt, self.data, start)[0]

    def stamp_ns(self) -> int:
        sec = self.scalar('i')
        nanosec = self.scalar('I')
        return sec * NS_PER_S + nanosec

    def string(self) -> str:
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


class PartStatesData(NamedTuple):
    """Decoded PartStates: stamp [ns], frame id, step and the per-part arrays (SI units)."""

    stamp_ns: int
    frame_id: str
    step: int
    id: np.ndarray
    part_type: np.ndarray
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    wz: np.ndarray


def decode_part_states(data: bytes) -> PartStatesData:
    """Decode a PartStates message.

    :param data: CDR bytes including the encapsulation header.
    :raises CdrError: on malformed data or arrays of unequal length.
    """
    r = _Reader(data, 'PartStates')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    step = r.scalar('Q')
    arrays = [r.array('u4'), r.array('u2')] + [r.array('f8') for _ in _F64_FIELDS]
    if len({len(a) for a in arrays}) > 1:
        raise CdrError(f'PartStates arrays differ in length: {[len(a) for a in arrays]}')
    return PartStatesData(stamp_ns, frame_id, step, *arrays)


class DensityGridData(NamedTuple):
    """Decoded DensityGrid; ``density`` has shape (ny, nx) [parts/m^2]."""

    stamp_ns: int
    frame_id: str
    step: int
    zone: str
    origin_x: float
    origin_y: float
    resolution: float
    density: np.ndarray
    total_parts: float


def decode_density_grid(data: bytes) -> DensityGridData:
    """Decode a DensityGrid message.

    :param data: CDR bytes including the encapsulation header.
    :raises CdrError: on malformed data or a density whose size is not ``nx*ny``.
    """
    r = _Reader(data, 'DensityGrid')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    step = r.scalar('Q')
    zone = r.string()
    origin_x, origin_y, resolution = r.scalar('d'), r.scalar('d'), r.scalar('d')
    nx, ny = r.scalar('I'), r.scalar('I')
    density = r.array('f4')
    if density.size != nx * ny:
        raise CdrError(f'DensityGrid: {density.size} values for a {nx} x {ny} grid')
    total = r.scalar('d')
    return DensityGridData(stamp_ns, frame_id, step, zone, origin_x, origin_y, resolution,
                           density.reshape(ny, nx), total)


def decode_light_barrier_states(data: bytes) -> Tuple[int, str, int, Tuple[str, ...],
                                                         np.ndarray, np.ndarray]:
    """Decode a LightBarrierStates message.

    :return: ``(stamp_ns, frame_id, step, names, blocked (bool), edge_count (uint32))``.
    :raises CdrError: on malformed data.
    """
    r = _Reader(data, 'LightBarrierStates')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    step = r.scalar('Q')
    names = tuple(r.string() for _ in range(r.scalar('I')))
    blocked = r.array('u1').astype(bool)
    edge_count = r.array('u4')
    return stamp_ns, frame_id, step, names, blocked, edge_count


def _decode_command(data: bytes, type_name: str) -> Tuple[str, float, str, int]:
    r = _Reader(data, type_name)
    name, value = r.string(), r.scalar('d')
    if r.at_end():  # recorded before commands carried a sender and a sequence number
        return name, value, '', 0
    return name, value, r.string(), r.scalar('I')


def decode_belt_command(data: bytes) -> Tuple[str, float]:
    """Decode a BeltCommand message (also one recorded without ``sender`` and ``sequence``).

    :return: ``(belt, speed)``, speed [m/s].
    :raises CdrError: on malformed data.
    """
    return _decode_command(data, 'BeltCommand')[:2]


def decode_actuator_command(data: bytes) -> Tuple[str, float]:
    """Decode an ActuatorCommand message (also one recorded without ``sender`` and
    ``sequence``).

    :return: ``(actuator, position)``, position [m] or [rad].
    :raises CdrError: on malformed data.
    """
    return _decode_command(data, 'ActuatorCommand')[:2]


def decode_command_origin(data: bytes, type_name: str = 'BeltCommand') -> Tuple[str, int]:
    """Return ``(sender, sequence)`` of BeltCommand or ActuatorCommand CDR bytes (``''``, 0
    for bytes without them).

    :raises CdrError: on malformed data.
    """
    return _decode_command(data, type_name)[2:]


def encode_spawn_request(part_type: str, x: Sequence[float], y: Sequence[float],
                         yaw: Sequence[float]) -> bytes:
    """Return the CDR bytes of a SpawnParts request; poses [m], [rad]."""
    b = _Builder()
    b.string(part_type)
    for values in (x, y, yaw):
        b.u32(len(values))
        for v in values:
            b.f64(float(v))
    return b.message()


def decode_spawn_request(data: bytes) -> Tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """Decode a SpawnParts request.

    :return: ``(part_type, x, y, yaw)``, poses [m], [rad].
    :raises CdrError: on malformed data.
    """
    r = _Reader(data, 'SpawnParts_Request')
    return r.string(), r.array('f8'), r.array('f8'), r.array('f8')


def encode_reset_request(cell_file: str, seed: int) -> bytes:
    """Return the CDR bytes of a Reset request."""
    b = _Builder()
    b.string(cell_file)
    b.u64(int(seed))
    return b.message()


def decode_reset_request(data: bytes) -> Tuple[str, int]:
    """Decode a Reset request: ``(cell_file, seed)``.

    :raises CdrError: on malformed data.
    """
    r = _Reader(data, 'Reset_Request')
    return r.string(), r.scalar('Q')


def decode_clock(data: bytes) -> int:
    """Decode a rosgraph_msgs/Clock message and return its time [ns].

    :raises CdrError: on malformed data.
    """
    return _Reader(data, 'Clock').stamp_ns()
