"""What the harness may wait for while ``stream_outage`` faults silence streams.

The latched ``faults`` stream states the active faults from a stamp on; :class:`OutageTimeline`
keeps every such statement, so the harness knows which streams were silent at any step.
:class:`EdgeAccount` counts the light-barrier edges the harness can expect: the edges the
``light_barriers`` counts added in the steps in which ``light_barrier_edges`` was published
(edges counted while it was silenced are never sent, so are never waited for).
"""

import bisect
from typing import Dict, FrozenSet, List, Sequence, Tuple

from conveyor_twin.contract import LIGHT_BARRIER_EDGES
from conveyor_twin.wire import cdr
from conveyor_twin.wire.decoders import decode_fault_state

EDGES = LIGHT_BARRIER_EDGES.name


class OutageTimeline:
    """The streams silenced by ``stream_outage`` faults, by simulation time [ns]."""

    def __init__(self) -> None:
        self._seen = 0
        self._stamps: List[int] = []
        self._silenced: List[FrozenSet[str]] = []
        self._faults: List[Dict[str, int]] = []

    def update(self, messages: Sequence[bytes]) -> bool:
        """Take the ``faults`` messages not seen yet; return True if any was new."""
        if len(messages) < self._seen:  # forgotten (reset): start again
            self.__init__()
        new = messages[self._seen:]
        for data in new:
            state = decode_fault_state(data)
            outages = {f.target: f.id for f in state.active if f.kind == 'stream_outage'}
            self._stamps.append(state.stamp_ns)
            self._silenced.append(frozenset(outages))
            self._faults.append(outages)
        self._seen = len(messages)
        return bool(new)

    def silenced_at(self, stamp_ns: int) -> FrozenSet[str]:
        """Return the streams silenced at the step of ``stamp_ns``."""
        i = bisect.bisect_right(self._stamps, stamp_ns)
        return self._silenced[i - 1] if i else frozenset()

    def silenced_in(self, after_ns: int, until_ns: int) -> Tuple[FrozenSet[str], FrozenSet[str]]:
        """Return (silenced at some step, silenced at every step) of the steps in
        ``(after_ns, until_ns]``."""
        states = [self.silenced_at(after_ns + 1)]
        lo = bisect.bisect_right(self._stamps, after_ns + 1)
        hi = bisect.bisect_right(self._stamps, until_ns)
        states += self._silenced[lo:hi]
        return frozenset().union(*states), frozenset.intersection(*states)

    def latest(self) -> Dict[str, int]:
        """Return the streams silenced now, as the latest statement says: ``{stream: fault id}``."""
        return dict(self._faults[-1]) if self._faults else {}

    def describe(self) -> str:
        """Name the active stream outages, for an error message."""
        latest = self.latest()
        if not latest:
            return 'no stream outage active'
        return 'active stream outages: ' + ', '.join(
            f'{s} (fault {i})' for s, i in sorted(latest.items()))


class EdgeAccount:
    """The light-barrier edges the harness can expect, from the barrier counts and outages.

    Incremental: a new ``faults`` statement recounts from the start (rare); new barrier
    states are added as they come.
    """

    def __init__(self) -> None:
        self.timeline = OutageTimeline()
        self._totals: List[Tuple[int, int]] = []  # (stamp, sum of edge counts) per message
        self._counted = 0   # totals taken into ``_expected``
        self._expected = 0

    def expected(self, barrier_states: Sequence[bytes], faults: Sequence[bytes]) -> int:
        """Return the number of edges published up to the latest barrier state received."""
        if len(barrier_states) < len(self._totals):  # forgotten (reset)
            self._totals, self._counted, self._expected = [], 0, 0
        for data in barrier_states[len(self._totals):]:
            counts = cdr.decode_light_barrier_states(data)[5]
            self._totals.append((cdr.stamp_of(data), int(sum(counts))))
        if self.timeline.update(faults):
            self._counted, self._expected = 0, 0
        for i in range(self._counted, len(self._totals)):
            stamp, total = self._totals[i]
            before_stamp, before = self._totals[i - 1] if i else (-1, 0)
            anywhere, _ = self.timeline.silenced_in(before_stamp, stamp)
            if EDGES not in anywhere:  # published at every step since the last state
                self._expected += max(0, total - before)
        self._counted = len(self._totals)
        return self._expected
