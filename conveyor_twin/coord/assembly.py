"""The one place that assembles a twin (no ROS imports): :func:`build_twin`.

A twin of a cell runs in one of four layouts:

- ``composed``: one process steps everything: the coordinator core (:class:`Twin`: time,
  commands, actuation) with the micro stage, the macro stage and the
  :class:`~conveyor_twin.coord.scale.ScaleCoupling` between them, in that order;
- split over three processes, each process builds its role:
  ``coordinator`` (the :class:`Twin` without stages: its step inputs go to the scale processes),
  ``micro`` (the micro stage and, for cells with ``macro``/``auto`` zones, the micro half of the
  hand-over: :class:`~conveyor_twin.coord.mirror.MicroSide`) and ``macro`` (the macro stage and
  the hand-over on a mirror of the micro state: :class:`~conveyor_twin.coord.mirror.MacroSide`).

Every part gets what it works with through its constructor: the micro stage the holder of the
light barriers in ``macro`` zones, the coupling the stages and that holder; nothing attaches
itself to another object afterwards. The ROS nodes (``conveyor_twin.ros``) wrap what this
builds; tests and tools use it directly::

    twin = build_twin(load_cell(), seed=1)            # composed
    twin.twin.commands.submit_belt('main', 0.3)
    twin.step(1000)
    twin.micro.parts()                                # (id, type, x, y, yaw, vx, vy, wz)
"""

from dataclasses import dataclass
from typing import Callable, Dict, Literal, Optional, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord import codec
from conveyor_twin.coord.codec import MACRO_ROLE, MICRO_ROLE
from conveyor_twin.coord.mirror import has_coupling, MacroSide, MicroSide
from conveyor_twin.coord.requests import SpawnRequest
from conveyor_twin.coord.scale import ScaleCoupling
from conveyor_twin.coord.stages import MacroStage, MicroStage
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coord.twin import Twin
from conveyor_twin.coord.zone_barriers import MacroZoneBarriers, RemoteBarriers
from conveyor_twin.faults.scenario import Scenario, ScenarioRunner

Layout = Literal['composed', 'coordinator', 'micro', 'macro']
LAYOUTS: Tuple[str, ...] = ('composed', 'coordinator', 'micro', 'macro')


@dataclass
class AssembledTwin:
    """What :func:`build_twin` built for one layout; the parts a layout lacks are None.

    :param layout: ``composed``, ``coordinator``, ``micro`` or ``macro``.
    :param twin: the coordinator core (``composed`` and ``coordinator``).
    :param micro: the micro stage (``composed`` and ``micro``).
    :param macro: the macro stage (``composed`` and ``macro``).
    :param coupling: the scale hand-over (``composed``; in ``macro``, the one on the mirror).
    :param micro_side: the micro half of the hand-over (``micro``, cells with macro zones).
    :param macro_side: the macro half of the hand-over (``macro``, cells with macro zones).
    """

    layout: str
    cell: Cell
    seed: int
    twin: Optional[Twin] = None
    micro: Optional[MicroStage] = None
    macro: Optional[MacroStage] = None
    coupling: Optional[ScaleCoupling] = None
    micro_side: Optional[MicroSide] = None
    macro_side: Optional[MacroSide] = None

    @property
    def remote_roles(self) -> Tuple[int, ...]:
        """Roles of the scale processes the coordinator waits for every step (``coordinator``
        layout: micro and macro; else none)."""
        return (MICRO_ROLE, MACRO_ROLE) if self.layout == 'coordinator' else ()

    def step(self, n: int = 1) -> StepInput:
        """Advance ``n`` steps (``composed``); return the last step's input."""
        if self.layout != 'composed':
            raise ValueError(f'only the composed layout steps by itself, not {self.layout!r}')
        return self.twin.step(n)

    def arm_scenario(self, scenario: Scenario, *,
                     edge_count: Optional[Callable[[], np.ndarray]] = None,
                     zone_parts_of: Optional[Callable[[int], float]] = None) -> ScenarioRunner:
        """Arm a fault scenario on the coordinator core (``composed`` and ``coordinator``);
        re-armed after every reset. Its triggers read the stages here (``composed``) or what
        the scale nodes measured (``coordinator``: ``edge_count``, ``zone_parts_of``, from
        their step replies, see :meth:`trigger_measures`).

        :raises ValueError: for a scenario with triggers and nothing to read them from.
        """
        twin = self.twin
        if twin is None:
            raise ValueError(f'the {self.layout} layout has no coordinator core')
        micro, macro = self.micro, self.macro
        if micro is not None:
            edge_count = micro.barrier_edge_count

            def zone_parts_of(index: int) -> float:
                return zone_parts(self.cell, micro, macro, index)
        runner = ScenarioRunner(scenario, twin.faults, edge_count=edge_count,
                                zone_parts=zone_parts_of)
        twin.fault_watchers.append(runner.watch)
        twin.reset_listeners.append(runner.arm)
        return runner

    def trigger_measures(self) -> Callable[[], bytes]:
        """Return what a split scale node sends after every step when the scenario has
        triggers on the cell's state (``micro``: barrier edge counts and bodies per zone;
        ``macro``: density parts per zone), :func:`~conveyor_twin.coord.codec.encode_measures`
        bytes."""
        cell, zones = self.cell, range(len(self.cell.zones))
        if self.layout == 'micro':
            micro = self.micro
            return lambda: codec.encode_measures(
                micro.barrier_edge_count(),
                np.array([micro_zone_parts(cell, micro, i) for i in zones]))
        if self.layout == 'macro':
            macro = self.macro
            return lambda: codec.encode_measures(
                np.zeros(0, np.uint32), np.array([macro_zone_parts(cell, macro, i)
                                                  for i in zones]))
        raise ValueError(f'the {self.layout} layout is no scale node')

    def spawn(self, request: SpawnRequest) -> np.ndarray:
        """Place a checked spawn request's parts now (all or nothing); return their ids.

        :raises ValueError: if a pose overlaps anything or the capacity is exhausted, or this
            layout holds no micro stage.
        """
        if self.micro is None:
            raise ValueError(f'the {self.layout} layout holds no micro stage to spawn into')
        return self.micro.spawn(request.type_index, request.x, request.y, request.yaw)

    def micro_counters(self) -> Dict[str, float]:
        """Part balance of the micro stage: entered, left, in flight."""
        return self.micro.counters() if self.micro is not None else {}

    def macro_counters(self) -> Dict[str, float]:
        """Part balance of the macro stage, with the whole cell's ledger (``balance_*``) when
        the hand-over runs here."""
        if self.macro is None:
            return {}
        out = self.macro.counters()
        if self.coupling is not None:
            out.update(self.coupling.balance_counters())
        return out

    def reset_scales(self, cell: Cell, seed: int) -> None:
        """Restart the stages of a split scale role (``micro`` or ``macro``); the coordinator
        core resets its own stages (:meth:`Twin.reset`)."""
        if self.micro is not None:
            self.micro.reset(cell, seed)
            if self.micro_side is not None:
                self.micro_side.reset()
        if self.macro is not None:
            self.macro.reset(cell, seed)
            if self.macro_side is not None:
                self.macro_side.reset(cell, 0)  # the mirror never runs sources
        self.cell, self.seed = cell, seed


def build_twin(cell: Cell, *, seed: int, layout: Layout = 'composed',
               check_balance: Optional[bool] = None) -> AssembledTwin:
    """Build a twin of ``cell`` for ``layout``.

    :param cell: the validated cell.
    :param seed: random seed of the run (sources).
    :param layout: ``composed`` (everything here), or one role of the split layout:
        ``coordinator``, ``micro`` or ``macro``.
    :param check_balance: check the part ledger after every hand-over (raises
        :class:`~conveyor_twin.coord.scale.BalanceError`); None reads the environment variable
        ``CONVEYOR_TWIN_CHECK_BALANCE``.
    :raises ValueError: for an unknown layout.
    """
    if layout == 'composed':
        barriers = MacroZoneBarriers()
        micro = MicroStage(cell, seed, macro_barriers=barriers)
        macro = MacroStage(cell, seed)
        coupling = ScaleCoupling(micro, macro, barriers=barriers, check=check_balance)
        twin = Twin(cell, seed=seed, stages=[micro, macro, coupling])
        return AssembledTwin(layout, cell, seed, twin=twin, micro=micro, macro=macro,
                             coupling=coupling)
    if layout == 'coordinator':
        return AssembledTwin(layout, cell, seed, twin=Twin(cell, seed=seed))
    coupled = has_coupling(cell)
    if layout == 'micro':
        if not coupled:
            return AssembledTwin(layout, cell, seed, micro=MicroStage(cell, seed))
        remote = RemoteBarriers()
        micro = MicroStage(cell, seed, macro_barriers=remote)
        return AssembledTwin(layout, cell, seed, micro=micro,
                             micro_side=MicroSide(micro, remote))
    if layout == 'macro':
        macro = MacroStage(cell, seed)
        if not coupled:
            return AssembledTwin(layout, cell, seed, macro=macro)
        # the mirror never runs sources: its seed does not matter
        side = MacroSide(macro, cell, 0, check=check_balance)
        return AssembledTwin(layout, cell, seed, macro=macro, coupling=side.coupling,
                             macro_side=side)
    allowed = ', '.join(LAYOUTS)
    raise ValueError(f'unknown layout {layout!r} (allowed: {allowed})')


def zone_parts(cell: Cell, micro: MicroStage, macro: Optional[MacroStage], index: int) -> float:
    """Return the parts in zone ``index``: bodies with their centre in it, plus the parts of
    its macro density (if it has a grid) [parts]."""
    return micro_zone_parts(cell, micro, index) + macro_zone_parts(cell, macro, index)


def micro_zone_parts(cell: Cell, micro: MicroStage, index: int) -> float:
    """Return the bodies with their centre in zone ``index`` [parts]."""
    x0, y0, x1, y1 = cell.zones[index].region
    v = micro.sim.parts_view()
    return float(np.count_nonzero((v.x >= x0) & (v.x <= x1) & (v.y >= y0) & (v.y <= y1)))


def macro_zone_parts(cell: Cell, macro: Optional[MacroStage], index: int) -> float:
    """Return the parts of zone ``index``'s macro density (0 without a grid) [parts]."""
    if macro is None:
        return 0.0
    name = cell.zones[index].name
    return sum(g.total_parts() for g in macro.grids if g.zone.name == name)
