"""The scale cores behind the coordinator's per-step interface (no ROS imports).

:class:`MicroStage` wraps :class:`~conveyor_twin.micro.sim.MicroSim`, :class:`MacroStage` one
:class:`~conveyor_twin.macro.solver.MacroSim` per zone whose policy is ``macro``. Each takes
the coordinator's :class:`StepInput` (actual belt speeds and actuator positions of the step),
so both scales see the same actuation whatever the process layout.

Scale hand-over between zones (issue 6) is not wired yet: the micro scale simulates the whole
cell and the macro grids evolve independently.
"""

from typing import Dict, List, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.clock import step_ns
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.macro.solver import MacroSim
from conveyor_twin.micro.errors import SpawnOverlapError
from conveyor_twin.micro.sim import MicroSim

_EMPTY_EDGES = (np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, np.int64),
                np.zeros(0, np.uint32))


class MicroStage:
    """Micro scale of a cell: every part a rigid body.

    :param cell: the validated cell. :param seed: the run's seed.
    """

    def __init__(self, cell: Cell, seed: int) -> None:
        self.reset(cell, seed)

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart from an empty cell."""
        self.cell = cell
        self.sim = MicroSim(cell, seed=seed)
        self._dt_ns = step_ns(cell.settings.step)
        self._edges = _EMPTY_EDGES

    def advance(self, inp: StepInput) -> None:
        """Apply the step's actuation, advance one step, collect its barrier edges."""
        self.sim.apply_actuation(inp.belt_speed, inp.actuator_position)
        self.sim.step(1)
        if self.sim.event_count:
            ev = self.sim.drain_events()
            time_ns = np.rint(ev.time * 1e9).astype(np.int64)
            self._edges = (ev.barrier, ev.blocked, time_ns, ev.part_id)
        else:
            self._edges = _EMPTY_EDGES

    def parts(self) -> Tuple[np.ndarray, ...]:
        """Return (id, part_type, x, y, yaw, vx, vy, wz) of every part, views [SI]."""
        v = self.sim.parts_view()
        return v.id, v.part_type, v.x, v.y, v.yaw, v.vx, v.vy, v.wz

    def barrier_blocked(self) -> np.ndarray:
        """Blocked flag of every light barrier at the end of the step."""
        return self.sim.blocked

    def barrier_edge_count(self) -> np.ndarray:
        """Edges seen so far by every light barrier (uint32)."""
        return self.sim.edge_count

    def edges(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return the last step's edges: (barrier index, blocked, time [ns], part id)."""
        return self._edges

    def spawn(self, part_type: int, x: np.ndarray, y: np.ndarray,
              yaw: np.ndarray) -> np.ndarray:
        """Place parts now (all or nothing); return their ids.

        :raises ValueError: if a pose overlaps anything or the capacity is exhausted.
        """
        try:
            return self.sim.spawn(part_type, x, y, yaw)
        except SpawnOverlapError as exc:
            raise ValueError(f'nothing placed: {exc}') from None
        except Exception as exc:  # capacity and index errors, named for the caller
            raise ValueError(f'nothing placed: {exc}') from None

    def counters(self) -> Dict[str, int]:
        """Part balance: entered, left (through sinks), in flight."""
        c = self.sim.counters()
        return {'entered': c['entered'], 'left': c['left'], 'in_flight': c['in_flight']}


class MacroStage:
    """Macro scale: the density of every zone whose policy is ``macro``."""

    def __init__(self, cell: Cell, seed: int = 0) -> None:
        self.reset(cell, seed)

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart with empty grids."""
        self.cell = cell
        self.grids: List[MacroSim] = [MacroSim(cell, zone) for zone in cell.zones
                                      if zone.policy == 'macro']
        self.names = [g.zone.name for g in self.grids]

    def advance(self, inp: StepInput) -> None:
        """Apply the step's actuation and advance every grid one step."""
        for grid in self.grids:
            grid.set_belt_speeds(inp.belt_speed)
            grid.set_actuator_positions(inp.actuator_position)
            grid.step(1)

    def counters(self) -> Dict[str, float]:
        """Part balance over all grids: entered, left, in flight (fractional parts)."""
        return {'entered': float(sum(g.parts_in + g.parts_deposited for g in self.grids)),
                'left': float(sum(g.parts_out + g.parts_taken for g in self.grids)),
                'in_flight': float(sum(g.total_parts() for g in self.grids))}
