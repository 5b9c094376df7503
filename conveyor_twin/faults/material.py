"""Material faults on the micro scale: a part that jams, parts that fall off, sources that surge
or deliver the wrong type (no ROS imports).

- ``part_jam``: the part (by id, or the one nearest to (x, y) when the fault takes effect, within
  its bounding radius) keeps the pose it had then, at rest, after every step; other parts
  collide with it as with any part and are held up. A request naming a part id the micro
  scale does not hold when it is made is rejected (:func:`holds_part`; the coordinator asks
  the micro stage, in the split layout over the coupling). If the part leaves the micro
  scale before the next step, or no part is near (x, y), the fault holds nothing.
- ``parts_vanish``: after every step the parts whose centre lies in the rectangle are removed
  and counted as ``vanished`` in the part ledger.
- ``source_surge``: the source's rate is multiplied by ``factor``; ``source_wrong_type``: it
  delivers ``part_type``. Both are undone when cleared.

The density of ``macro``/``auto`` zones in a vanishing rectangle is removed by the scale
hand-over (:class:`~conveyor_twin.coupling.scale.ScaleCoupling`), which owns the per-type ledger.
"""

from typing import Dict, Sequence, Tuple

import numpy as np

from conveyor_twin.faults.book import CLEAR, FaultEvent
from conveyor_twin.micro.sim import MicroSim
from conveyor_twin.micro.sources import SR_RATE, SR_TYPE
from conveyor_twin.micro.state import P_VX, P_VY, P_WZ, P_X, P_X_PREV, P_Y, P_Y_PREV, P_YAW, \
    P_YAW_PREV, PT_BRAD

_KINDS = ('part_jam', 'parts_vanish', 'source_surge', 'source_wrong_type')


def holds_part(sim: MicroSim, part_id: int) -> bool:
    """True if the micro scale holds a part of id ``part_id`` now (a ``part_jam`` target)."""
    ids = sim.parts_view().id
    row = int(np.searchsorted(ids, part_id))
    return row < len(ids) and int(ids[row]) == int(part_id)


class MaterialFaults:
    """The material faults of a micro stage."""

    def __init__(self) -> None:
        self.jams: Dict[int, Tuple[int, np.ndarray]] = {}   # fault id -> (part id, pose)
        self.regions: Dict[int, Tuple[float, float, float, float]] = {}
        self._sources: Dict[int, Tuple[int, int, float]] = {}  # fault id -> (source, column, old)

    @property
    def busy(self) -> bool:
        """True while a jam or a vanishing region acts after every step."""
        return bool(self.jams or self.regions)

    def apply(self, events: Sequence[FaultEvent], sim: MicroSim) -> None:
        """Take the step's events (before the step)."""
        for event in events:
            fault = event.fault
            if fault.kind not in _KINDS:
                continue
            if event.action == CLEAR:
                self.jams.pop(fault.id, None)
                self.regions.pop(fault.id, None)
                undo = self._sources.pop(fault.id, None)
                if undo is not None:
                    source, column, old = undo
                    sim.src[source, column] = old
                continue
            if fault.kind == 'part_jam':
                part = self._find(sim, fault.index, fault.param('x'), fault.param('y'))
                if part is not None:
                    self.jams[fault.id] = part
            elif fault.kind == 'parts_vanish':
                p = dict(fault.params)
                self.regions[fault.id] = (p['x0'], p['y0'], p['x1'], p['y1'])
            else:
                column = SR_RATE if fault.kind == 'source_surge' else SR_TYPE
                self._sources[fault.id] = (fault.index, column,
                                           float(sim.src[fault.index, column]))
                sim.src[fault.index, column] = (sim.src[fault.index, column]
                                                * fault.param('factor')
                                                if column == SR_RATE else fault.part_type_index)

    @staticmethod
    def _find(sim: MicroSim, part_id: int, x: float, y: float):
        """Return (id, pose x, y, yaw) of the part to jam, or None."""
        v = sim.parts_view()
        if part_id >= 0:
            row = int(np.searchsorted(v.id, part_id))
            if row >= len(v.id) or v.id[row] != part_id:
                return None
        else:
            if not len(v.id):
                return None
            d2 = (v.x - x) ** 2 + (v.y - y) ** 2
            row = int(np.argmin(d2))
            if d2[row] > sim.pt[v.part_type[row], PT_BRAD] ** 2:
                return None
        return int(v.id[row]), np.array([v.x[row], v.y[row], v.yaw[row]])

    def after_step(self, sim: MicroSim) -> None:
        """Hold jammed parts at their pose, remove the parts in vanishing regions."""
        s = sim.state
        n = sim.n
        for part_id, pose in self.jams.values():
            row = int(np.searchsorted(s.ids[:n], part_id))
            if row < n and s.ids[row] == part_id:
                s.P[P_X, row], s.P[P_Y, row], s.P[P_YAW, row] = pose
                s.P[P_X_PREV, row], s.P[P_Y_PREV, row], s.P[P_YAW_PREV, row] = pose
                s.P[P_VX, row] = s.P[P_VY, row] = s.P[P_WZ, row] = 0.0
        for x0, y0, x1, y1 in self.regions.values():
            n = sim.n
            x, y = s.P[P_X, :n], s.P[P_Y, :n]
            mask = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
            if mask.any():
                sim.vanish(mask)
