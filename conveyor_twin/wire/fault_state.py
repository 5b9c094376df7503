"""CDR of ``conveyor_twin_msgs/FaultState``: the active faults, sent when they change."""

from typing import List, NamedTuple, Sequence, Tuple

import numpy as np

from conveyor_twin.wire.cdr import _Builder, _Reader


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
    b = _Builder()
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


def decode_fault_state(data: bytes) -> FaultStateData:
    """Decode a FaultState message.

    :raises CdrError: on malformed data.
    """
    r = _Reader(data, 'FaultState')
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
