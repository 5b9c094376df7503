"""Light-barrier faults: what a controller sees of a barrier that sticks, chatters, lags or
loses edges (no ROS imports).

:class:`BarrierFaults` sits between a barrier's true signal (micro or, in ``macro`` zones, the
density model) and the ``light_barriers``/``light_barrier_edges`` streams. Per faulted barrier:

- ``barrier_stuck_blocked`` / ``barrier_stuck_free``: the reported state is fixed; one edge
  (part id 0) at the step the state changes;
- ``barrier_chatter``: the reported state toggles every half period (blocked first), an edge at
  each toggle;
- ``barrier_delay``: every true edge is reported ``delay`` later (whole steps), the state
  follows the reported edges;
- ``barrier_drop_edges``: each true edge is lost with ``probability`` (the state stays true).

The edge counter counts reported edges. When the fault is cleared the barrier reports its true
state again (one edge if it differs). With several faults on one barrier the latest injected
rules.
"""

from typing import Dict, List, Sequence, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.faults.book import CLEAR, fault_rng, FaultEvent, steps_of
from conveyor_twin.faults.model import ActiveFault

Edges = Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # barrier, blocked, t [ns], id
_KINDS = ('barrier_stuck_blocked', 'barrier_stuck_free', 'barrier_chatter', 'barrier_delay',
          'barrier_drop_edges')


class BarrierFaults:
    """The light-barrier faults of a stage and what they report.

    :param cell: the cell. :param seed: the run's seed (edge drops draw from it).
    """

    def __init__(self, cell: Cell, seed: int) -> None:
        self.seed = seed
        self.dt = cell.settings.step
        self.n = len(cell.light_barriers)
        self.faults: Dict[int, Tuple[ActiveFault, int]] = {}  # barrier -> (fault, first step)
        self._rng = {}
        self._reported = np.zeros(self.n, dtype=bool)
        self._offset = np.zeros(self.n, dtype=np.int64)  # reported - true edge count
        self._counts_differ = False  # _offset has a non-zero entry
        self._delayed: List[Tuple[int, int, bool, int, int]] = []  # due, b, blocked, t, id
        self._released = np.zeros(self.n, dtype=bool)  # cleared this step: report truth
        self._any_released = False
        self.dropped = 0

    @property
    def busy(self) -> bool:
        """True while a barrier fault is active or has just been cleared (:meth:`filter` must
        run); otherwise only the edge counters may differ (:meth:`count`)."""
        return bool(self.faults) or self._any_released

    def count(self, count: np.ndarray) -> np.ndarray:
        """Return the reported edge counters of true ``count`` (edges added or lost by faults
        stay counted after they are cleared)."""
        if not self._counts_differ:
            return count
        return (count.astype(np.int64) + self._offset).astype(count.dtype)

    def apply(self, events: Sequence[FaultEvent], blocked: np.ndarray) -> None:
        """Take the step's events; ``blocked`` is every barrier's true state before the step."""
        for event in events:
            fault = event.fault
            if fault.kind not in _KINDS:
                continue
            b = fault.index
            current = self.faults.get(b)
            if event.action == CLEAR:
                if current is not None and current[0].id == fault.id:
                    del self.faults[b]
                    self._released[b] = True
                    self._any_released = True
                    self._delayed = [d for d in self._delayed if d[1] != b]
                continue
            if current is None:
                self._reported[b] = blocked[b]
            self.faults[b] = (fault, event.step)
            self._rng[fault.id] = fault_rng(self.seed, fault.id)

    def filter(self, step: int, time_ns: int, blocked: np.ndarray, count: np.ndarray,
               edges: Edges) -> Tuple[np.ndarray, np.ndarray, Edges]:
        """Return the reported (blocked, edge count, edges) of the step from the true ones."""
        bar, rising, t, part = edges
        keep = np.ones(len(bar), dtype=bool)
        out_blocked = blocked.copy()
        extra: List[Tuple[int, bool, int, int]] = []
        for b, (fault, start) in self.faults.items():
            mine = bar == b
            kind = fault.kind
            if kind == 'barrier_drop_edges':
                rng = self._rng[fault.id]
                for i in np.flatnonzero(mine):
                    if rng.random() < fault.param('probability'):
                        keep[i] = False
                        self.dropped += 1
                self._reported[b] = blocked[b]
                continue
            keep &= ~mine
            if kind == 'barrier_delay':
                due = step + steps_of(fault.param('delay'), self.dt)
                shift = (due - step) * int(round(self.dt * 1e9))
                self._delayed += [(due, b, bool(rising[i]), int(t[i]) + shift, int(part[i]))
                                  for i in np.flatnonzero(mine)]
                state = self._reported[b]
                for d in [d for d in self._delayed if d[0] <= step and d[1] == b]:
                    extra.append((b, d[2], d[3], d[4]))
                    state = d[2]
                self._delayed = [d for d in self._delayed if not (d[0] <= step and d[1] == b)]
            else:
                if kind == 'barrier_stuck_blocked':
                    state = True
                elif kind == 'barrier_stuck_free':
                    state = False
                else:  # chatter: blocked in the first half of every period
                    half = (step - start) * self.dt * 2.0 * fault.param('frequency')
                    state = int(half + 1e-9) % 2 == 0
                if state != self._reported[b]:
                    extra.append((b, state, time_ns, 0))
            self._reported[b] = state
            out_blocked[b] = state
        for b in np.flatnonzero(self._released):
            if blocked[b] != self._reported[b]:
                extra.append((int(b), bool(blocked[b]), time_ns, 0))
            self._reported[b] = blocked[b]
        self._released[:] = False
        self._any_released = False
        # edge counter: reported = true + offset
        lost = np.bincount(bar[~keep], minlength=self.n) if len(bar) else 0
        added = np.bincount([e[0] for e in extra], minlength=self.n) if extra else 0
        self._offset += added - lost
        self._counts_differ = bool(self._offset.any())
        out_count = self.count(count)
        if extra or not keep.all():
            bar = np.concatenate([bar[keep], np.array([e[0] for e in extra], dtype=bar.dtype)])
            rising = np.concatenate([rising[keep], np.array([e[1] for e in extra], dtype=bool)])
            t = np.concatenate([t[keep], np.array([e[2] for e in extra], dtype=np.int64)])
            part = np.concatenate([part[keep], np.array([e[3] for e in extra],
                                                        dtype=part.dtype)])
        return out_blocked, out_count, (bar, rising, t, part)
