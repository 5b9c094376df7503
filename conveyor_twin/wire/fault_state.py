"""CDR of ``conveyor_twin_msgs/FaultState``: the active faults, sent when they change.

The decoder is :func:`conveyor_twin.wire.decoders.decode_fault_state`.
"""

from typing import NamedTuple, Sequence, Tuple

from conveyor_twin.wire.builder import CdrBuilder


class FaultEntry(NamedTuple):
    """One active fault as the message carries it (times [s])."""

    id: int
    kind: str
    target: str
    params: Tuple[Tuple[str, float], ...]
    part_type: str
    duration: float
    since: float


class FaultStateData(NamedTuple):
    """A decoded FaultState message."""

    stamp_ns: int
    frame_id: str
    active: Tuple[FaultEntry, ...]
    injected: Tuple[int, ...]
    cleared: Tuple[int, ...]
    cleared_reason: Tuple[str, ...]
    total_injected: int
    total_rejected: int


def encode_fault_state(stamp_ns: int, frame_id: str, active: Sequence[FaultEntry],
                       injected: Sequence[int], cleared: Sequence[Tuple[int, str]],
                       total_injected: int, total_rejected: int) -> bytes:
    """Return the CDR bytes of a FaultState message.

    :param stamp_ns: simulation time from which the set is in effect [ns].
    :param cleared: (id, reason) of the faults cleared at this stamp.
    """
    b = CdrBuilder()
    b.stamp(stamp_ns)
    b.string(frame_id)

    def u32s(values: Sequence[int]) -> None:
        b.u32(len(values))
        for v in values:
            b.u32(int(v))

    def f64s(values: Sequence[float]) -> None:
        b.u32(len(values))
        for v in values:
            b.f64(float(v))

    u32s([f.id for f in active])
    b.strings([f.kind for f in active])
    b.strings([f.target for f in active])
    u32s([len(f.params) for f in active])
    b.strings([name for f in active for name, _ in f.params])
    f64s([value for f in active for _, value in f.params])
    b.strings([f.part_type for f in active])
    f64s([f.duration for f in active])
    f64s([f.since for f in active])
    u32s(list(injected))
    u32s([i for i, _ in cleared])
    b.strings([reason for _, reason in cleared])
    b.u32(total_injected)
    b.u32(total_rejected)
    return b.message()
