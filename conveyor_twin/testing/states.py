"""What the harness reads from the twin's streams, as plain values (SI units)."""

from typing import NamedTuple

from conveyor_twin.testing.driver import CommandResult


class BeltState(NamedTuple):
    """A belt as ``belt_states`` last reported it: speeds [m/s]."""

    commanded_speed: float
    speed: float


class ActuatorState(NamedTuple):
    """An actuator as ``actuator_states`` last reported it: positions [m] or [rad], whether it
    is stalled and the parts' load on it [N]."""

    commanded_position: float
    position: float
    stalled: bool = False
    load: float = 0.0


class BeltSample(NamedTuple):
    """One belt in one ``belt_states`` message: its stamp [ns] and speeds [m/s]."""

    stamp_ns: int
    commanded: float
    actual: float


class BarrierState(NamedTuple):
    """A light barrier as ``light_barriers`` last reported it."""

    blocked: bool
    edge_count: int


class Edge(NamedTuple):
    """A light-barrier edge (``light_barrier_edges``).

    :param name: the barrier
    :param blocked: True when the beam became interrupted
    :param part_id: the part (0 for an edge of the macro scale)
    :param time_ns: interpolated simulation time of the edge [ns]
    :param step: the step during which it happened
    """

    name: str
    blocked: bool
    part_id: int
    time_ns: int
    step: int


class CommandRecord(NamedTuple):
    """A command the twin answered on ``command_status`` (from the harness or a controller).

    :param topic: ``belt_command`` or ``actuator_command``
    :param target: the belt or actuator named in the command
    :param value: commanded speed [m/s] or position [m] or [rad]
    :param result: accepted, or rejected with the reason
    :param sender: the ``sender`` the command carried ('' when none)
    :param sequence: the sender's ``sequence`` number of it (0 when none)
    """

    topic: str
    target: str
    value: float
    result: CommandResult
    sender: str = ''
    sequence: int = 0
