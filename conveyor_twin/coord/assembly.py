"""The composed twin, assembled in one place (no ROS imports): :func:`build_twin`.

Composed, one process steps everything: the coordinator core (:class:`Twin`: time, commands,
actuation) with the micro stage, the macro stage and the
:class:`~conveyor_twin.coupling.scale.ScaleCoupling` between them, in that order. (The split
layout's processes are assembled by their roles, :mod:`conveyor_twin.split.roles`.)

Every part gets what it works with through its constructor: the micro stage the holder of the
light barriers in ``macro`` zones, the coupling the stages and that holder; nothing attaches
itself to another object afterwards. The ROS nodes (``conveyor_twin.ros``) wrap what this
builds; tests and tools use it directly::

    twin = build_twin(load_cell(), seed=1)
    twin.twin.commands.submit_belt('main', 0.3)
    twin.step(1000)
    twin.micro.parts()                                # (id, type, x, y, yaw, vx, vy, wz)
"""

from dataclasses import dataclass
from typing import Dict, Optional

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.requests import SpawnRequest
from conveyor_twin.coord.stages import MacroStage, MicroStage
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coord.twin import Twin
from conveyor_twin.coupling.scale import ScaleCoupling
from conveyor_twin.coupling.zone_barriers import MacroZoneBarriers
from conveyor_twin.faults.material import holds_part
from conveyor_twin.faults.scenario import Scenario, ScenarioRunner


@dataclass
class AssembledTwin:
    """What :func:`build_twin` built: the composed twin and its parts.

    :param twin: the coordinator core; its stages are ``micro``, ``macro``, ``coupling``.
    :param micro: the micro stage.
    :param macro: the macro stage.
    :param coupling: the scale hand-over on the micro and macro stages.
    """

    cell: Cell
    seed: int
    twin: Twin
    micro: MicroStage
    macro: MacroStage
    coupling: ScaleCoupling

    def step(self, n: int = 1) -> StepInput:
        """Advance ``n`` steps; return the last step's input."""
        return self.twin.step(n)

    def arm_scenario(self, scenario: Scenario) -> ScenarioRunner:
        """Arm a fault scenario on the coordinator core (re-armed after every reset); its
        triggers read the stages."""
        cell, micro, macro = self.cell, self.micro, self.macro

        def zone_parts_of(index: int) -> float:
            return zone_parts(cell, micro, macro, index)
        runner = ScenarioRunner(scenario, self.twin.faults,
                                edge_count=micro.barrier_edge_count, zone_parts=zone_parts_of)
        self.twin.fault_watchers.append(runner.watch)
        self.twin.reset_listeners.append(runner.arm)
        return runner

    def spawn(self, request: SpawnRequest) -> np.ndarray:
        """Place a checked spawn request's parts now (all or nothing); return their ids.

        :raises ValueError: if a pose overlaps anything or the capacity is exhausted.
        """
        return self.micro.spawn(request.type_index, request.x, request.y, request.yaw)

    def holds_part(self, part_id: int) -> bool:
        """Return True if the micro stage holds a part ``part_id`` now (``part_jam``)."""
        return holds_part(self.micro.sim, part_id)

    def micro_counters(self) -> Dict[str, float]:
        """Part balance of the micro stage: entered, left, in flight."""
        return self.micro.counters()

    def macro_counters(self) -> Dict[str, float]:
        """Part balance of the macro stage, with the whole cell's ledger (``balance_*``)."""
        out = self.macro.counters()
        out.update(self.coupling.balance_counters())
        return out


def build_twin(cell: Cell, *, seed: int, check_balance: Optional[bool] = None) -> AssembledTwin:
    """Build the composed twin of ``cell``.

    :param cell: the validated cell.
    :param seed: random seed of the run (sources).
    :param check_balance: check the part ledger after every hand-over (raises
        :class:`~conveyor_twin.coupling.scale.BalanceError`); None reads the environment variable
        ``CONVEYOR_TWIN_CHECK_BALANCE``.
    """
    barriers = MacroZoneBarriers()
    micro = MicroStage(cell, seed, macro_barriers=barriers)
    macro = MacroStage(cell, seed)
    coupling = ScaleCoupling(micro, macro, barriers=barriers, check=check_balance)
    twin = Twin(cell, seed=seed, stages=[micro, macro, coupling],
                actuator_load=micro.actuator_load if cell.actuators else None)
    return AssembledTwin(cell, seed, twin=twin, micro=micro, macro=macro, coupling=coupling)


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
