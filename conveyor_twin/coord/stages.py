"""The scale cores behind the coordinator's per-step interface (no ROS imports).

:class:`MicroStage` wraps :class:`~conveyor_twin.micro.sim.MicroSim`, :class:`MacroStage` one
:class:`~conveyor_twin.macro.solver.MacroSim` per zone whose policy is ``macro``. Each takes
the coordinator's :class:`StepInput` (actual belt speeds and actuator positions of the step),
so both scales see the same actuation whatever the process layout.

Scale hand-over: the micro scale simulates the whole cell; a
:class:`~conveyor_twin.coupling.scale.ScaleCoupling` stepped after both stages moves parts and mass
between them, and light barriers in ``macro`` zones take their values and edges from the density
(:mod:`conveyor_twin.coupling.zone_barriers`): the micro stage is built with the holder of those
values (:mod:`conveyor_twin.coord.assembly` wires the composed layout,
:mod:`conveyor_twin.split.roles` the split one).
"""

from typing import Dict, List, Optional, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.clock import step_ns
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coupling.zone_barriers import BarrierOverlay
from conveyor_twin.faults.barriers import BarrierFaults
from conveyor_twin.faults.material import MaterialFaults
from conveyor_twin.macro.solver import MacroSim
from conveyor_twin.micro.errors import SpawnOverlapError
from conveyor_twin.micro.sim import MicroSim

_EMPTY_EDGES = (np.zeros(0, np.int64), np.zeros(0, bool), np.zeros(0, np.int64),
                np.zeros(0, np.uint32))


class MicroStage:
    """Micro scale of a cell: every part a rigid body.

    :param cell: the validated cell. :param seed: the run's seed.
    :param macro_barriers: the values and edges of the light barriers in ``macro`` zones,
        published in place of the micro ones (None: every barrier is micro).
    """

    label = 'micro'   # its part of a step's time (:class:`~.timing.StepParts`)

    def __init__(self, cell: Cell, seed: int, *,
                 macro_barriers: Optional[BarrierOverlay] = None) -> None:
        self.macro_barriers = macro_barriers
        self.reset(cell, seed)

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart from an empty cell."""
        self.cell = cell
        self.sim = MicroSim(cell, seed=seed)
        self._dt_ns = step_ns(cell.settings.step)
        self._edges = _EMPTY_EDGES
        #: Light-barrier and material faults (their events arrive with the step input).
        self.barrier_faults = BarrierFaults(cell, seed)
        self.material_faults = MaterialFaults()
        self._step = 0
        self._time_ns = 0
        self._reported_step = -1
        self._reported = None

    def advance(self, inp: StepInput) -> None:
        """Apply the step's faults and actuation, advance one step, collect its barrier
        edges."""
        if inp.faults:
            self.barrier_faults.apply(inp.faults, self._true_blocked())
            self.material_faults.apply(inp.faults, self.sim)
        self.sim.apply_actuation(inp.belt_speed, inp.actuator_position)
        self.sim.step(1)
        if self.material_faults.busy:
            self.material_faults.after_step(self.sim)
        self._step = inp.step
        self._time_ns = inp.time_ns
        if self.sim.event_count:
            ev = self.sim.drain_events()
            time_ns = np.rint(ev.time * 1e9).astype(np.int64)
            self._edges = (ev.barrier, ev.blocked, time_ns, ev.part_id)
        else:
            self._edges = _EMPTY_EDGES

    def actuator_load(self) -> np.ndarray:
        """Mean normal force the parts put on every actuator during the last step [N]."""
        return self.sim.actuator_load

    def parts(self) -> Tuple[np.ndarray, ...]:
        """Return (id, part_type, x, y, yaw, vx, vy, wz) of every part, views [SI]."""
        v = self.sim.parts_view()
        return v.id, v.part_type, v.x, v.y, v.yaw, v.vx, v.vy, v.wz

    def _with_macro_barriers(self, micro_values: np.ndarray, attribute: str) -> np.ndarray:
        """Return ``micro_values`` (one per barrier) with the entries of barriers in macro
        zones replaced by their macro model's ``attribute`` (the array itself if there are
        none)."""
        c = self.macro_barriers
        if c is None or not c.barriers:
            return micro_values
        out = micro_values.copy()
        for b in c.barriers:
            out[b.index] = getattr(b, attribute)
        return out

    def barrier_blocked(self) -> np.ndarray:
        """Blocked flag of every light barrier at the end of the step, as reported (faults
        applied)."""
        if self._faults_apply():
            return self._faulted()[0]
        return self._true_blocked()

    def barrier_edge_count(self) -> np.ndarray:
        """Edges reported so far by every light barrier (uint32)."""
        if self._faults_apply():
            return self._faulted()[1]
        return self.barrier_faults.count(self._true_edge_count())

    def edges(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return the last step's reported edges: (barrier index, blocked, time [ns], part id).

        Edges of barriers in macro zones come after the micro ones, with part id 0; edges made
        by faults last, with part id 0.
        """
        if self._faults_apply():
            return self._faulted()[2]
        return self._true_edges()

    def _faults_apply(self) -> bool:
        """True if this step's barrier values go through the faults (decided once a step)."""
        return self._reported_step == self._step or self.barrier_faults.busy

    def _faulted(self) -> tuple:
        """The step's (blocked, edge count, edges) through the barrier faults, once a step."""
        if self._reported_step != self._step:
            self._reported = self.barrier_faults.filter(
                self._step, self._time_ns, self._true_blocked(), self._true_edge_count(),
                self._true_edges())
            self._reported_step = self._step
        return self._reported

    def _true_blocked(self) -> np.ndarray:
        return self._with_macro_barriers(self.sim.blocked, 'blocked')

    def _true_edge_count(self) -> np.ndarray:
        return self._with_macro_barriers(self.sim.edge_count, 'edge_count')

    def _true_edges(self) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        c = self.macro_barriers
        if c is None or not c.barriers:
            return self._edges
        ev = c.macro_edges
        idx = np.array([e[0] for e in ev], dtype=np.int64)
        blocked = np.array([e[1] for e in ev], dtype=bool)
        t = np.rint(np.array([e[2] for e in ev], dtype=float) * 1e9).astype(np.int64)
        b, k, tt, p = self._edges
        own = ~np.isin(b, c.macro_barrier_index)  # barriers in macro zones: macro edges only
        b, k, tt, p = b[own], k[own], tt[own], p[own]
        return (np.concatenate([b, idx]), np.concatenate([k, blocked]),
                np.concatenate([tt, t]), np.concatenate([p, np.zeros(len(ev), np.uint32)]))

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
        """Part balance: entered, left (through sinks and deleted), in flight, vanished (fault
        ``parts_vanish``) once a part fell off, deleted once a part was deleted."""
        c = self.sim.counters()
        out = {'entered': c['entered'], 'left': c['left'], 'in_flight': c['in_flight']}
        if c['vanished']:
            out['vanished'] = c['vanished']
        if c['deleted']:  # included in left
            out['deleted'] = c['deleted']
        return out


class MacroStage:
    """Macro scale: the density of every zone whose policy is ``macro`` or ``auto``."""

    label = 'macro'

    def __init__(self, cell: Cell, seed: int = 0) -> None:
        self.reset(cell, seed)

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart with empty grids."""
        self.cell = cell
        self.grids: List[MacroSim] = [MacroSim(cell, zone) for zone in cell.zones
                                      if zone.policy in ('macro', 'auto')]
        self.names = [g.zone.name for g in self.grids]

    def advance(self, inp: StepInput) -> None:
        """Apply the step's actuation and advance every grid one step."""
        for grid in self.grids:
            grid.set_belt_speeds(inp.belt_speed)
            grid.set_actuator_positions(inp.actuator_position)
            grid.step(1)

    def counters(self) -> Dict[str, float]:
        """Part balance over all grids: entered, left, in flight (fractional parts).

        (The whole cell's ledger is the scale coupling's:
        :meth:`~conveyor_twin.coupling.scale.ScaleCoupling.balance_counters`.)
        """
        return {'entered': float(sum(g.parts_in + g.parts_deposited for g in self.grids)),
                'left': float(sum(g.parts_out + g.parts_taken for g in self.grids)),
                'in_flight': float(sum(g.total_parts() for g in self.grids))}
