"""CDR encoders of the contract messages, straight from numpy (see :mod:`.builder` for the format).

Every encoder returns the complete serialized message as rmw_fastrtps produces it: the
encapsulation header followed by the payload, padding zeroed, so equal inputs give equal bytes.

The hot streams (``parts``, ``density``, ``light_barriers``, ``belt_states``,
``actuator_states``) have encoder classes that precompute the fixed parts once per stream
(frame id, names, grid geometry) and fill a reusable, 8-byte aligned numpy buffer; each call
returns an immutable ``bytes`` copy, which can be handed to ``Publisher.publish`` and to the
recorder at the same time. Encoder instances are not thread-safe; the module-level
``encode_*`` functions keep one cached encoder per thread and per fixed part.

Times are integer nanoseconds of simulation time (``stamp_ns``).
"""

import threading
from typing import Any, Dict, Hashable, Sequence

import numpy as np

from conveyor_twin.wire.builder import (align, CdrBuffer, CdrBuilder, CdrError,
                                        ENCAPSULATION_LE, F64, header_prefix, STAMP,
                                        stamp_parts, U32, U64)

_F64_FIELDS = ('x', 'y', 'yaw', 'vx', 'vy', 'wz')


class PartStatesEncoder:
    """Encoder of ``conveyor_twin_msgs/PartStates`` for one stream (fixed frame id)."""

    def __init__(self, frame_id: str = 'cell', capacity: int = 1024) -> None:
        """Create the encoder.

        :param frame_id: ``header.frame_id`` of every message.
        :param capacity: number of parts the buffer is sized for at first (it grows).
        """
        self.frame_id = frame_id
        self._head = header_prefix(frame_id)
        self._p_step = align(len(self._head), 8)
        self._capacity = -1
        self._n = -1
        self._reserve(capacity)

    def _reserve(self, n: int) -> None:
        if n > self._capacity:
            self._capacity = max(n, 2 * self._capacity)
            self._buf = CdrBuffer(self._p_step + 64 + 54 * self._capacity)
            self._n = -1

    def _layout(self, n: int) -> None:
        """Set the layout (offsets, lengths, views) for ``n`` parts; zero all padding."""
        self._reserve(n)
        buf = self._buf
        buf.raw[:] = 0
        buf.raw[4:8] = np.frombuffer(ENCAPSULATION_LE, dtype=np.uint8)
        buf.put(0, self._head)
        p = self._p_step + 8
        buf.put(p, U32.pack(n))
        self._v_id = buf.view(p + 4, n, '<u4')
        p += 4 + 4 * n
        p = align(p, 4)
        buf.put(p, U32.pack(n))
        self._v_type = buf.view(p + 4, n, '<u2')
        p += 4 + 2 * n
        views = []
        for _ in _F64_FIELDS:
            p = align(p, 4)
            buf.put(p, U32.pack(n))
            p += 4
            if n:
                p = align(p, 8)
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
        STAMP.pack_into(raw, 8, *stamp_parts(stamp_ns))
        U64.pack_into(raw, 8 + self._p_step, step)
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
        b = CdrBuilder()
        b.buf.extend(header_prefix(frame_id))
        self._p_step = align(b.pos, 8)
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
        self._p_total = align(b.pos, 8)
        b.f64(0.0)
        self._size = b.pos
        self._buf = CdrBuffer(self._size)
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
        STAMP.pack_into(raw, 8, *stamp_parts(stamp_ns))
        U64.pack_into(raw, 8 + self._p_step, step)
        self._v_density[...] = flat
        F64.pack_into(raw, 8 + self._p_total, total_parts)
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
        b = CdrBuilder()
        b.buf.extend(header_prefix(frame_id))
        self._p_step = align(b.pos, 8)
        b.u64(0)
        b.strings(self.names)
        b.u32(n)
        p_blocked = b.pos
        b.buf.extend(bytes(n))
        b.u32(n)
        p_count = b.pos
        b.buf.extend(bytes(4 * n))
        self._size = b.pos
        self._buf = CdrBuffer(self._size)
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
        STAMP.pack_into(raw, 8, *stamp_parts(stamp_ns))
        U64.pack_into(raw, 8 + self._p_step, step)
        np.not_equal(blocked, 0, out=self._v_blocked, casting='unsafe')
        self._v_count[...] = edge_count
        return self._buf.message(self._size)


class _NamedPairEncoder:
    """Encoder of a message ``header, string[] name, float64[] a, float64[] b``."""

    def __init__(self, frame_id: str, names: Sequence[str]) -> None:
        self.names = tuple(names)
        n = self.count = len(self.names)
        b = CdrBuilder()
        b.buf.extend(header_prefix(frame_id))
        b.strings(self.names)
        views = []
        for _ in range(2):
            b.u32(n)
            if n:
                b.align(8)
            views.append(b.pos)
            b.buf.extend(bytes(8 * n))
        self._size = b.pos
        self._buf = CdrBuffer(self._size)
        self._buf.put(0, bytes(b.buf))
        self._v_a_pos, self._v_b_pos = views
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
        STAMP.pack_into(self._buf.raw, 8, *stamp_parts(stamp_ns))
        self._v_a[...] = commanded
        self._v_b[...] = actual
        return self._buf.message(self._size)


class BeltStatesEncoder(_NamedPairEncoder):
    """Encoder of ``conveyor_twin_msgs/BeltStates``: speeds [m/s] of fixed belt names."""


class ActuatorStatesEncoder(_NamedPairEncoder):
    """Encoder of ``conveyor_twin_msgs/ActuatorStates``: positions [m or rad], stall flags and
    loads [N] of fixed names."""

    def __init__(self, frame_id: str, names: Sequence[str]) -> None:
        super().__init__(frame_id, names)
        n = self.count
        b = CdrBuilder()
        b.buf.extend(self._buf.raw[8:8 + self._size].tobytes())  # the pair layout, then more
        b.u32(n)
        p_stalled = b.pos
        b.buf.extend(bytes(n))
        b.u32(n)
        if n:
            b.align(8)
        p_load = b.pos
        b.buf.extend(bytes(8 * n))
        self._size = b.pos
        self._buf = CdrBuffer(self._size)
        self._buf.put(0, bytes(b.buf))
        self._v_a = self._buf.view(self._v_a_pos, n, '<f8')
        self._v_b = self._buf.view(self._v_b_pos, n, '<f8')
        self._v_stalled = self._buf.view(p_stalled, n, np.uint8)
        self._v_load = self._buf.view(p_load, n, '<f8')

    def encode(self, stamp_ns: int, commanded: Any, actual: Any, stalled: Any = None,
               load: Any = None) -> bytes:
        """Return the CDR bytes of one message.

        :param commanded: last accepted target positions; ``actual``: actual positions
            [m or rad]; ``stalled``: true while stalled (None: none); ``load``: normal force of
            the parts on each actuator in the step [N] (None: zeros); one per name.
        :raises CdrError: on arrays whose length differs from the names.
        """
        for label, values in (('stalled', stalled), ('load', load)):
            if values is not None and len(values) != self.count:
                raise CdrError(f'ActuatorStates: {len(values)} {label} values for '
                               f'{self.count} names')
        if stalled is None:
            self._v_stalled[...] = 0
        else:
            np.not_equal(stalled, 0, out=self._v_stalled, casting='unsafe')
        if load is None:
            self._v_load[...] = 0.0
        else:
            self._v_load[...] = load
        return super().encode(stamp_ns, commanded, actual)


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
                           commanded_position: Any, position: Any, stalled: Any = None,
                           load: Any = None) -> bytes:
    """Return the CDR bytes of an ActuatorStates message; positions [m] or [rad], stall
    flags (None: none stalled), loads [N] (None: zeros)."""
    names = tuple(names)
    encoder = _cached(ActuatorStatesEncoder, (frame_id, names), frame_id, names)
    return encoder.encode(stamp_ns, commanded_position, position, stalled, load)


def encode_light_barrier_edge(stamp_ns: int, frame_id: str, name: str, blocked: bool,
                              part_id: int) -> bytes:
    """Return the CDR bytes of a LightBarrierEdge message.

    :param stamp_ns: interpolated simulation time of the edge [ns].
    :param frame_id: ``header.frame_id``.
    :param name: light barrier name.
    :param blocked: true if the beam became interrupted.
    :param part_id: id of the micro part causing the edge, 0 for the macro scale.
    """
    b = CdrBuilder()
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
    return ENCAPSULATION_LE + STAMP.pack(*stamp_parts(stamp_ns))


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
    b = CdrBuilder()
    b.string(name)
    b.f64(value)
    b.string(sender)
    b.u32(sequence)
    return b.message()


def encode_spawn_request(part_type: str, x: Sequence[float], y: Sequence[float],
                         yaw: Sequence[float]) -> bytes:
    """Return the CDR bytes of a SpawnParts request; poses [m], [rad]."""
    b = CdrBuilder()
    b.string(part_type)
    for values in (x, y, yaw):
        b.u32(len(values))
        for v in values:
            b.f64(float(v))
    return b.message()


def encode_reset_request(cell_file: str, seed: int) -> bytes:
    """Return the CDR bytes of a Reset request."""
    b = CdrBuilder()
    b.string(cell_file)
    b.u64(int(seed))
    return b.message()
