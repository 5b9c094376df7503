"""Light barriers in ``macro`` zones as the micro stage publishes them (no ROS imports).

The micro stage publishes every light barrier; a barrier inside a ``macro`` zone sees no micro
parts, so its values and edges come from the density instead. Both holders below carry what the
micro stage reads (``barriers`` with ``index``/``blocked``/``edge_count``, the step's
``macro_edges`` as (barrier index, blocked, time [s]), ``macro_barrier_index``); the assembly
(:mod:`conveyor_twin.coord.assembly`) hands the same holder to the micro stage and to whoever
fills it:

- :class:`MacroZoneBarriers`: composed (and in the macro process of the split layout), the
  barriers modelled on the macro grids (:mod:`conveyor_twin.coupling.macro_barriers`), advanced by
  the :class:`~conveyor_twin.coupling.scale.ScaleCoupling` after its hand-over;
- :class:`RemoteBarriers`: in the micro process of the split layout, the values decoded from
  the macro process's reply (:class:`~conveyor_twin.split.mirror.MicroSide`).
"""

from typing import List, NamedTuple, Protocol, Sequence, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coupling.macro_barriers import MacroBarrier
from conveyor_twin.macro.solver import MacroSim

Edge = Tuple[int, bool, float]  # barrier index, blocked, time [s]


class BarrierOverlay(Protocol):
    """What the micro stage reads of the barriers in ``macro`` zones."""

    barriers: Sequence
    macro_edges: List[Edge]
    macro_barrier_index: np.ndarray


class BarrierValue(NamedTuple):
    """One light barrier in a ``macro`` zone as the micro stage publishes it."""

    index: int
    blocked: bool
    edge_count: int


def _inside(barrier, sim: MacroSim) -> bool:
    g = sim.grid
    x1, y1 = g.origin_x + g.nx * g.h, g.origin_y + g.ny * g.h
    mx = 0.5 * (barrier.start[0] + barrier.end[0])
    my = 0.5 * (barrier.start[1] + barrier.end[1])
    return g.origin_x <= mx <= x1 and g.origin_y <= my <= y1


class MacroZoneBarriers:
    """The light barriers whose beam midpoint lies on a ``macro`` zone's grid, modelled on it."""

    def __init__(self) -> None:
        self.barriers: List[MacroBarrier] = []
        self.macro_edges: List[Edge] = []
        self.macro_barrier_index = np.zeros(0, dtype=np.int64)

    def bind(self, cell: Cell, grids: Sequence[MacroSim]) -> None:
        """Model every barrier of ``cell`` on the first of ``grids`` (``macro`` zones) holding
        its beam's midpoint; the others stay micro."""
        self.barriers = []
        for index, barrier in enumerate(cell.light_barriers):
            for sim in grids:
                if _inside(barrier, sim):
                    self.barriers.append(MacroBarrier(index, barrier, sim,
                                                      cell.part_types[0].bounding_radius))
                    break
        self.macro_barrier_index = np.array([b.index for b in self.barriers], dtype=np.int64)
        self.macro_edges = []

    def advance(self, dt: float, t_end: float) -> None:
        """Advance every barrier over the step ending at ``t_end``; collect its edges.

        :param dt: step [s]. :param t_end: simulation time at the end of the step [s].
        """
        self.macro_edges = []
        for barrier in self.barriers:
            barrier.advance(dt, t_end, self.macro_edges)


class RemoteBarriers:
    """The barriers of ``macro`` zones as received from another process (split layout)."""

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Forget every value (after a reset)."""
        self.barriers: List[BarrierValue] = []
        self.macro_edges: List[Edge] = []
        self.macro_barrier_index = np.zeros(0, dtype=np.int64)

    def load(self, barriers: Sequence[Tuple[int, bool, int]], edges: List[Edge]) -> None:
        """Take the values of the step: barriers as (index, blocked, edge_count), its edges."""
        self.barriers = [BarrierValue(*b) for b in barriers]
        self.macro_barrier_index = np.array([b.index for b in self.barriers], dtype=np.int64)
        self.macro_edges = edges
