"""CDR decoders of every contract message, into numpy arrays and named tuples (SI units).

Each decoder takes the complete CDR bytes (encapsulation header included, little or big
endian), reads them with the bounds-checked :class:`~conveyor_twin.wire.reader.CdrReader` and
raises :class:`~conveyor_twin.wire.builder.CdrError` on malformed data.
"""

from typing import List, NamedTuple, Tuple

import numpy as np

from conveyor_twin.wire.builder import CdrError
from conveyor_twin.wire.diagnostics import Status
from conveyor_twin.wire.fault_state import FaultEntry, FaultStateData
from conveyor_twin.wire.reader import CdrReader


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
    r = CdrReader(data, 'PartStates')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    step = r.scalar('Q')
    arrays = [r.array('u4'), r.array('u2')] + [r.array('f8') for _ in range(6)]
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
    r = CdrReader(data, 'DensityGrid')
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
    r = CdrReader(data, 'LightBarrierStates')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    step = r.scalar('Q')
    names = tuple(r.string() for _ in range(r.scalar('I')))
    blocked = r.array('u1').astype(bool)
    edge_count = r.array('u4')
    return stamp_ns, frame_id, step, names, blocked, edge_count


def _decode_command(data: bytes, type_name: str) -> Tuple[str, float, str, int]:
    r = CdrReader(data, type_name)
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


def decode_spawn_request(data: bytes) -> Tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """Decode a SpawnParts request.

    :return: ``(part_type, x, y, yaw)``, poses [m], [rad].
    :raises CdrError: on malformed data.
    """
    r = CdrReader(data, 'SpawnParts_Request')
    return r.string(), r.array('f8'), r.array('f8'), r.array('f8')


def decode_reset_request(data: bytes) -> Tuple[str, int]:
    """Decode a Reset request: ``(cell_file, seed)``.

    :raises CdrError: on malformed data.
    """
    r = CdrReader(data, 'Reset_Request')
    return r.string(), r.scalar('Q')


def decode_clock(data: bytes) -> int:
    """Decode a rosgraph_msgs/Clock message and return its time [ns].

    :raises CdrError: on malformed data.
    """
    return CdrReader(data, 'Clock').stamp_ns()


def density_zone(data: bytes) -> str:
    """Return the zone name of a DensityGrid without decoding its grid.

    :raises CdrError: on malformed data.
    """
    r = CdrReader(data, 'DensityGrid')
    r.stamp_ns()
    r.string()
    r.scalar('Q')
    return r.string()


class NamedPairData(NamedTuple):
    """Decoded BeltStates [m/s] or ActuatorStates [m or rad]; arrays indexed like ``names``."""

    stamp_ns: int
    frame_id: str
    names: Tuple[str, ...]
    commanded: np.ndarray
    actual: np.ndarray


def _named_pair(data: bytes, type_name: str) -> NamedPairData:
    r = CdrReader(data, type_name)
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    names = tuple(r.string() for _ in range(r.scalar('I')))
    commanded = r.array('f8')
    actual = r.array('f8')
    if not len(names) == len(commanded) == len(actual):
        msg = (f'{type_name}: {len(names)} names, {len(commanded)} commanded and '
               f'{len(actual)} actual values')
        raise CdrError(msg)
    return NamedPairData(stamp_ns, frame_id, names, commanded, actual)


def decode_belt_states(data: bytes) -> NamedPairData:
    """Decode a BeltStates message: commanded and actual speed per belt [m/s].

    :raises CdrError: on malformed data.
    """
    return _named_pair(data, 'BeltStates')


class ActuatorStatesData(NamedTuple):
    """Decoded ActuatorStates; arrays indexed like ``names``: positions [m or rad], ``stalled``
    (bool), ``load`` [N]."""

    stamp_ns: int
    frame_id: str
    names: Tuple[str, ...]
    commanded: np.ndarray
    actual: np.ndarray
    stalled: np.ndarray
    load: np.ndarray


def decode_actuator_states(data: bytes) -> ActuatorStatesData:
    """Decode an ActuatorStates message: commanded and actual position [m or rad], stall
    flags and loads [N] (a message of the earlier layout, without them: none stalled, zero).

    :raises CdrError: on malformed data.
    """
    r = CdrReader(data, 'ActuatorStates')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    names = tuple(r.string() for _ in range(r.scalar('I')))
    commanded = r.array('f8')
    actual = r.array('f8')
    if r.at_end():  # recorded before the stall fields existed
        stalled, load = np.zeros(len(names), bool), np.zeros(len(names))
    else:
        stalled = r.array('u1').astype(bool)
        load = r.array('f8')
    if not len(names) == len(commanded) == len(actual) == len(stalled) == len(load):
        msg = (f'ActuatorStates: {len(names)} names, {len(commanded)} commanded, '
               f'{len(actual)} actual, {len(stalled)} stalled and {len(load)} load values')
        raise CdrError(msg)
    return ActuatorStatesData(stamp_ns, frame_id, names, commanded, actual, stalled, load)


class EdgeData(NamedTuple):
    """Decoded LightBarrierEdge; ``stamp_ns`` is the interpolated time of the edge [ns]."""

    stamp_ns: int
    frame_id: str
    name: str
    blocked: bool
    part_id: int


def decode_light_barrier_edge(data: bytes) -> EdgeData:
    """Decode a LightBarrierEdge message.

    :raises CdrError: on malformed data.
    """
    r = CdrReader(data, 'LightBarrierEdge')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    name = r.string()
    blocked = bool(r.scalar('B'))
    part_id = r.scalar('I')
    return EdgeData(stamp_ns, frame_id, name, blocked, part_id)


def decode_fault_state(data: bytes) -> FaultStateData:
    """Decode a FaultState message.

    :raises CdrError: on malformed data.
    """
    r = CdrReader(data, 'FaultState')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()

    def strings() -> List[str]:
        return [r.string() for _ in range(r.scalar('I'))]

    ids = r.array('u4')
    kinds, targets = strings(), strings()
    counts = r.array('u4')
    names = strings()
    values = r.array('f8')
    part_types = strings()
    durations, since = r.array('f8'), r.array('f8')
    injected, cleared = r.array('u4'), r.array('u4')
    reasons = strings()
    total_injected, total_rejected = r.scalar('I'), r.scalar('I')
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(int)
    active = tuple(FaultEntry(int(ids[i]), kinds[i], targets[i],
                              tuple((names[k], float(values[k]))
                                    for k in range(offsets[i], offsets[i + 1])),
                              part_types[i], float(durations[i]), float(since[i]))
                   for i in range(len(ids)))
    return FaultStateData(stamp_ns, frame_id, active, tuple(int(i) for i in injected),
                          tuple(int(i) for i in cleared), tuple(reasons), total_injected,
                          total_rejected)


def decode_diagnostic_array(data: bytes) -> Tuple[int, str, Tuple[Status, ...]]:
    """Decode DiagnosticArray CDR bytes.

    :return: ``(stamp [ns], frame_id, statuses)``.
    :raises CdrError: on malformed data.
    """
    r = CdrReader(data, 'DiagnosticArray')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    statuses = []
    for _ in range(r.scalar('I')):
        level = r.scalar('B')
        name, message, hardware_id = r.string(), r.string(), r.string()
        values = tuple((r.string(), r.string()) for _ in range(r.scalar('I')))
        statuses.append(Status(level, name, message, hardware_id, values))
    return stamp_ns, frame_id, tuple(statuses)
