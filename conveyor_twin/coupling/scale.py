"""Scale coordination: micro and macro zones, exact hand-over, ``auto`` switching, the ledger.

:class:`ScaleCoupling` is a stage stepped after the micro and macro stages (the assembly,
:mod:`conveyor_twin.coord.assembly`, builds it with both and the light barriers of ``macro``
zones it advances). The micro simulator
covers the whole cell; every macro grid (zones of policy ``macro`` or ``auto``) has an ``active``
cell mask (all cells for ``macro``; the cells of macro tiles for ``auto``). Each step:

1. micro -> macro: micro parts whose centre lies in an active cell are removed and deposited as
   exactly one part's worth of mass over their footprint disc (active fluid cells only); their
   types go to the zone's type FIFO (below);
2. sinks: macro mass in cells whose centre lies in a sink, and boundary outflow through faces
   leading into a sink, leave the cell;
3. macro -> micro: boundary outflow accumulates per boundary face; mass that flowed into the
   inactive cells (micro tiles) of an ``auto`` zone stays in the density there and keeps
   flowing with the belt field, except that it is held back upstream where the micro parts of
   a cell leave no room (``rho_max h^2`` minus the part centres in it: the macro solver does
   not see micro parts, so without this it would pile onto a micro jam), and held back in
   front of sensor windows, whose cells take no density: every part that reaches a light
   barrier or an actuator there is a micro part (thin fronts are gathered, remainders with
   nothing behind them let past: :func:`~conveyor_twin.coupling.handover.gather_fronts`; density
   coming straight from a macro tile is released in the window's entrance cells, as deep as
   a release window needs to hold a whole part:
   :func:`~conveyor_twin.coupling.handover.entrance_depth`). Wherever a window of ``2 w + 1``
   neighbouring cells / faces (``w`` cells cover a part's radius) holds a whole part, one
   part is placed at the window's mass centre (outside the grid for faces) with the
   local belt velocity, without overlap: a lattice of part-diameter offsets over the whole
   window is tried, downstream along the local flow first, never onto an active cell (so it
   is not captured again) nor, on a grid with curved belts, onto a cell off the belts or
   solid, nor (from the density of micro tiles) beyond the grid's edge (so it does not land
   behind a guide rail); if all overlap, it waits. One part is
   taken from the window, the fractional remainder stays (in micro tiles it flows on, so
   remainders are not stranded);
4. ``auto`` zones re-evaluate their tiles (:mod:`conveyor_twin.coupling.tiles`); a tile that turns
   macro captures its parts in step 1 of the next step, one that turns micro releases its
   density as whole parts (count-exact, remainders carried);
5. light barriers in ``macro`` zones follow :mod:`conveyor_twin.coupling.macro_barriers`;
6. the ledger: ``entered = micro parts + integral of rho (active cells) + pending + left``
   where ``pending`` is the face accumulators plus the density in micro tiles not yet
   released; checked every step when ``check`` is on.

Part types (count-exact per type): each macro zone keeps a FIFO of the types of the parts it
captured, in capture order (within a step, in the micro simulator's order). Every released part
takes the type at the head; every whole part that leaves through a sink of the zone (the sink
outflow counted in whole parts, the fraction waits) takes the next one. So per type:
``entered = micro parts + held in the FIFO + left`` exactly, and the FIFO length matches the
macro mass (the ``type_residual`` of the ledger, checked with the mass ledger). Mass entering
by a prescribed macro inflow has no type: released from an empty FIFO it becomes type 0
(counted as ``untyped``). Parts released from the macro scale are new micro parts (new ids).

Arrival spread (boundary faces of ``macro`` zones): a uniform density fed into the windows of a
boundary face fills them all at the same pace, so they would release in lock-step rows (a beam
just downstream then stays blocked: 74 instead of 186 edges at 150 parts/s on the default
cell). Each face window therefore waits for ``1 + RELEASE_SPREAD u`` parts before its next
release (``u`` uniform in [0, 1), deterministic: PCG64 for the first phases, a 48-bit LCG per
grid after that), so the windows' phases are independent and their sum is close to the
Poisson arrivals of the micro flow (170 vs 186 edges at 150 parts/s, 1242 vs 1434 at 50
parts/s; more mass waits per window: up to ``1 + RELEASE_SPREAD`` parts). Windows inside
``auto`` zones release at one part (no spread).
"""

import math
import os
from typing import Dict, List, Optional, Protocol, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coupling import handover as _ho
from conveyor_twin.coupling.macro_barriers import MacroBarrier
from conveyor_twin.coupling.region import CLEARANCE, Region
from conveyor_twin.coupling.tiles import CHECK_STEPS, fill_cell_mask
from conveyor_twin.coupling.zone_barriers import MacroZoneBarriers
from conveyor_twin.faults.book import FaultEvent
from conveyor_twin.micro.sim import MicroSim

# Largest allowed |ledger residual| [parts] when checking.
BALANCE_TOLERANCE = 1e-9
# Environment switch that turns the per-step ledger check on (debug runs).
CHECK_ENV = 'CONVEYOR_TWIN_CHECK_BALANCE'
# Overlapping placements tried per step before the remaining releases wait for the next step.
MAX_FAILED_PLACEMENTS = 64
# Arrival spread of released parts [parts]: after each release a window must hold
# ``1 + RELEASE_SPREAD * u`` before the next part leaves, ``u`` uniform in [0, 1) from a
# deterministic generator (see the module docstring).
RELEASE_SPREAD = 3.0
# Generator state of the first grid's arrival spread (each further grid adds 7919).
JITTER_SEED = 0x5DEECE66D


class BalanceError(RuntimeError):
    """The part ledger does not balance (a hand-over lost or created mass)."""


class StepInfo(Protocol):
    """What the hand-over reads of a step's input (the coordinator's ``StepInput``)."""

    step: int
    time_ns: int  # the step's stamp [ns]
    faults: Tuple[FaultEvent, ...]  # faults injected or cleared at this step


class ScaleCoupling:
    """Hand-over between the micro stage and the macro stage's grids (a :class:`Stage`).

    :param micro_stage: the :class:`~conveyor_twin.coord.stages.MicroStage` (or a mirror of
        it: anything with the micro simulator as ``sim``).
    :param macro_stage: the :class:`~conveyor_twin.coord.stages.MacroStage`.
    :param barriers: the light barriers of ``macro`` zones this coupling binds to the grids and
        advances after each hand-over (the micro stage publishes them); None: a holder of its
        own.
    :param check: check the ledger every step (raise :class:`BalanceError`); None reads
        the environment variable ``CONVEYOR_TWIN_CHECK_BALANCE``.
    """

    label = 'hand-over'   # its part of a step's time

    def __init__(self, micro_stage, macro_stage, *,
                 barriers: Optional[MacroZoneBarriers] = None,
                 check: Optional[bool] = None) -> None:
        self.micro_stage = micro_stage
        self.macro_stage = macro_stage
        self.zone_barriers = barriers if barriers is not None else MacroZoneBarriers()
        if check is None:
            check = os.environ.get(CHECK_ENV, '') not in ('', '0')
        self.check = bool(check)
        self._bind()

    # --- set-up ---
    def _bind(self) -> None:
        self.micro: MicroSim = self.micro_stage.sim
        self.cell: Cell = self.micro.cell
        cell = self.cell
        self.part_type = 0
        self.n_types = len(cell.part_types)
        # the largest part sets the release spacing; the first type the macro barriers' length
        self.radius = max(p.bounding_radius for p in cell.part_types)
        self.regions = [Region(cell, sim, self.radius) for sim in self.macro_stage.grids]
        for k, region in enumerate(self.regions):
            region.seed_phases(RELEASE_SPREAD, JITTER_SEED + 7919 * k)
        self.captured_by_type = np.zeros(self.n_types, dtype=np.int64)
        self.released_by_type = np.zeros(self.n_types, dtype=np.int64)
        self.left_by_type = np.zeros(self.n_types, dtype=np.int64)
        self.left_macro = 0.0
        self.vanished_macro = 0.0  # mass of macro grids that fell off (fault parts_vanish)
        self.released = 0
        self.captured = 0
        self.step_index = 0
        self.max_residual = 0.0
        self._mask = np.zeros(self.micro.state.capacity, dtype=np.bool_)
        self._near = np.zeros(self.micro.state.capacity, dtype=np.int64)
        self._bnext = np.zeros(self.micro.state.capacity, dtype=np.int64)
        self._bhead = np.zeros(_ho.BUCKETS, dtype=np.int64)
        # footprint radius of each part type [m]: the disc of equal area
        self._radius_of_type = np.array([math.sqrt(p.footprint_area / math.pi)
                                         for p in cell.part_types])
        self._cand = np.zeros(5)
        self._tries = MAX_FAILED_PLACEMENTS
        self.zone_barriers.bind(cell, [r.sim for r in self.regions if r.tiles is None])

    def reset(self, cell: Cell, seed: int) -> None:
        """Rebind to the (reset) stages' new simulators."""
        self._bind()

    @property
    def enabled(self) -> bool:
        """True if the cell has macro grids to couple."""
        return bool(self.regions)

    @property
    def barriers(self) -> List[MacroBarrier]:
        """The light barriers modelled on ``macro`` zones' grids."""
        return self.zone_barriers.barriers

    @property
    def macro_edges(self) -> List[Tuple[int, bool, float]]:
        """The last step's edges of :attr:`barriers`: (barrier index, blocked, time [s])."""
        return self.zone_barriers.macro_edges

    def balance_counters(self) -> Dict[str, float]:
        """Return the ledger as counters (``balance_*``), empty without macro grids."""
        if not self.enabled:
            return {}
        return {f'balance_{k}': v for k, v in self.ledger().items()}

    # --- stepping ---
    def advance(self, inp: StepInfo) -> None:
        """Hand parts and mass over after the micro and macro steps of ``inp.step``."""
        self.step_index = inp.step
        if not self.regions:
            return
        if inp.faults:
            self._vanish_faults(inp)
        self._tries = MAX_FAILED_PLACEMENTS
        for region in self.regions:
            self._capture(region)
            self._sinks(region)
            if region.vanish:
                self._vanish(region)
            self._accumulate(region)
            self._release(region)
            if region.tiles is not None and inp.step % CHECK_STEPS == 0:
                self._switch(region, inp.step)
        self.zone_barriers.advance(self.cell.settings.step, inp.time_ns * 1e-9)
        if self.check:
            self.check_balance()

    def _vanish_faults(self, inp: StepInfo) -> None:
        """Take the step's ``parts_vanish`` events: the cells of each grid in the rectangle."""
        for event in inp.faults:
            fault = event.fault
            if fault.kind != 'parts_vanish':
                continue
            for region in self.regions:
                if event.action == 'clear':
                    region.vanish.pop(fault.id, None)
                    continue
                p = dict(fault.params)
                cells = region.cells_in(p['x0'], p['y0'], p['x1'], p['y1'])
                if len(cells):
                    region.vanish[fault.id] = cells

    def _vanish(self, region: Region) -> None:
        """Remove the mass in vanishing cells; count it ``vanished``, give whole parts types."""
        sim = region.sim
        for cells in region.vanish.values():
            taken = _ho.take_cells(sim.density, cells, sim.grid.h)
            if taken:
                region.vanished += taken
                self.vanished_macro += taken
                whole = int(math.floor(region.vanished)) - region.vanish_popped
                if whole > 0:
                    region.pop_types(whole)
                    region.vanish_popped += whole

    def _capture(self, region: Region) -> None:
        sim, g = region.sim, region.sim.grid
        micro = self.micro
        n = micro.n
        if n == 0:
            return
        P = micro.state
        x, y = P.P[0], P.P[1]
        mask = self._mask[:n]
        mask[:] = False
        count = _ho.capture_mask(x, y, n, g.origin_x, g.origin_y, g.h, region.active, mask)
        if count == 0:
            return
        parts = micro.remove(mask=mask)
        region.reserve_types(count)
        _ho.deposit_push(sim.density, region.active, sim.solid, g.origin_x, g.origin_y, g.h,
                         parts.x, parts.y, parts.part_type, self._radius_of_type, region.fifo,
                         region.fstate, self.captured_by_type)
        sim.parts_deposited += float(count)
        self.captured += count

    def _sinks(self, region: Region) -> None:
        sim = region.sim
        if region.has_sink_cells:
            taken = _ho.take_cells(sim.density, region.sink_index, sim.grid.h)
            if taken:
                sim.parts_taken += taken
                self._left(region, taken)

    def _left(self, region: Region, amount: float) -> None:
        """Count ``amount`` [parts] as left through a sink; give whole parts their types."""
        self.left_macro += amount
        region.left += amount
        whole = int(math.floor(region.left)) - region.sink_popped
        if whole > 0:
            types = region.pop_types(whole)
            region.sink_popped += whole
            self.left_by_type += np.bincount(types, minlength=self.n_types)[:self.n_types]

    def _accumulate(self, region: Region) -> None:
        sim = region.sim
        out = sim.outflow
        flags = _ho.accumulate_faces(out, region.face_sink, region.acc_flat, region.side_array)
        if flags:
            # outflow into sinks, summed per side as before (NumPy's summation order)
            for side, (a, b) in enumerate(region.sides):
                if flags >> side & 1:
                    left = float(out[a:b][region.face_sink[a:b]].sum())
                    if left:
                        self._left(region, left)
        if region.tiles is not None:
            self._hold_back(region)

    def _hold_back(self, region: Region) -> None:
        """Keep the density in micro tiles within the room the micro parts leave."""
        sim, g = region.sim, region.sim.grid
        v = self.micro.state.P
        _ho.hold_back_runs(sim.density, region.runs, region.n_runs, region.active, sim.solid,
                           sim.cell_velocity, g.origin_x, g.origin_y, g.h, sim.rho_max, v[0],
                           v[1], self.micro.n, region.occ, region.windows)
        if region.border.shape[0]:
            _ho.gather_fronts(sim.density, region.active, region.closed, sim.solid,
                              sim.cell_velocity, g.h, region.border, region.w, region.runs,
                              region.n_runs)

    def _release(self, region: Region) -> None:
        g = region.sim.grid
        vc = region.sim.cell_velocity
        _ho.side_max(region.acc_flat, region.side_array, region.acc_max)
        least = 1.0 / (2 * region.w + 1)  # a window of 2 w + 1 faces holds a part
        for side in range(4):
            if not (self._tries > 0 and region.acc_max[side] >= least):
                continue
            off = self.radius + CLEARANCE - 0.5 * g.h
            x_end, y_end = g.origin_x + g.nx * g.h, g.origin_y + g.ny * g.h
            ox, oy, vel, nx_, ny_ = (
                (g.origin_x - off - g.h, g.origin_y, vc[:, :1], -1.0, 0.0),
                (x_end + off, g.origin_y, vc[:, -1:], 1.0, 0.0),
                (g.origin_x, g.origin_y - off - g.h, vc[:1], 0.0, -1.0),
                (g.origin_x, y_end + off, vc[-1:], 0.0, 1.0))[side]
            self._release_from(region, region.face_acc[side], region.face_skip[side],
                               region.face_thr[side], 1.0, region.face_ranges[side], ox, oy,
                               vel, nx_, ny_, False, region.rng,
                               (region.grid_box, region.spot_refused))
        if region.tiles is not None and self._tries > 0 and region.ranges.shape[0]:
            # the density in micro tiles flows on until a window holds a whole part (on a grid
            # with curved belts never onto a spot beyond the grid: behind a curve's rail)
            spots = ((region.grid_box, region.spot_refused) if region.inner_refused is None
                     else (region.inner_box, region.inner_refused))
            self._release_from(region, region.sim.density, region.active, region.thr, g.h * g.h,
                               region.ranges, g.origin_x, g.origin_y, vc, 1.0, 0.0, True,
                               region.rng_inner, spots)

    def _release_from(self, region: Region, acc: np.ndarray, skip: np.ndarray,
                      thr: np.ndarray, unit: float, ranges: np.ndarray, ox: float, oy: float,
                      vel: np.ndarray, nx_: float, ny_: float, along_flow: bool,
                      rng: np.ndarray, refused: tuple) -> None:
        """Release whole parts from ``acc``; ``refused = (grid_box, mask)``: the spots no
        released part may take (see :func:`~conveyor_twin.coupling.handover.release_windows`)."""
        m = self.micro
        s = m.state
        w, h = region.w, region.sim.grid.h
        res = _ho.release_windows(
            (acc, skip, unit, thr, ranges), w,
            (ox, oy, h, vel, region.offsets, 2.0 * self.radius + CLEARANCE, nx_, ny_,
             along_flow, refused[0], refused[1]),
            self._tries, (self._cand, region.rot, self._near, self._bhead, self._bnext),
            (region.fifo, region.fstate, self.released_by_type, rng),
            (s.counters, s.ids, s.part_type, s.P, m.pt, m.shapes, m.shape_verts, m.act_state,
             m.act_verts, m._va, m._vb, m._out))
        if int(res[0]) and acc is region.sim.density:
            region.sim.parts_taken += float(res[0])
        self.released += int(res[0])
        self._tries -= int(res[1])

    def _switch(self, region: Region, step: int) -> None:
        tiles = region.tiles
        v = self.micro.parts_view()
        if not tiles.decide(step, v.x, v.y, v.vx, v.vy, self.micro.n, region.sim.density,
                            region.sim.cell_velocity):
            return
        self._apply_tiles(region)

    def _apply_tiles(self, region: Region) -> None:
        t = region.tiles
        fill_cell_mask(t.macro, t.tc, region.active)
        region.update_ranges()
        # the density of cells that turned micro is released as whole parts from now on

    def force_tiles(self, zone: str, macro: np.ndarray) -> None:
        """Set the tile modes of ``auto`` zone ``zone`` now (tests and tools).

        Parts in tiles turned macro are captured, and mass in tiles turned micro is released
        (as far as room allows), immediately.
        """
        for region in self.regions:
            if region.sim.zone.name == zone and region.tiles is not None:
                region.tiles.force(macro, self.step_index)
                self._apply_tiles(region)
                self._capture(region)
                self._tries = 1 << 30
                self._release(region)
                if self.check:
                    self.check_balance()
                return
        raise KeyError(f'no auto zone named {zone!r}')

    # --- ledger ---
    def ledger(self) -> Dict[str, float]:
        """Return the part balance [parts]: entered, micro, macro, pending, left, residual.

        ``entered`` counts parts from sources, spawn requests and macro inflow; parts released
        by the hand-over are not new. ``residual = entered - micro - macro - pending - left -
        vanished`` (``vanished``: parts that fell off the line, fault ``parts_vanish``).
        """
        c = self.micro.counters()
        micro_entered = c['entered'] - self.released
        macro_in = sum(r.sim.parts_in for r in self.regions)
        entered = float(micro_entered) + macro_in
        inactive = sum(r.inactive_mass() for r in self.regions)
        macro = sum(r.sim.total_parts() for r in self.regions) - inactive
        pending = sum(r.pending() for r in self.regions)
        left = float(c['left']) + self.left_macro
        micro_n = float(c['in_flight'])
        vanished = float(c.get('vanished', 0)) + self.vanished_macro
        residual = (entered - micro_n - macro - pending - left - float(c['handed_over'])
                    - vanished)
        out = {'entered': entered, 'micro': micro_n, 'macro': macro, 'pending': pending,
               'left': left, 'vanished': vanished, 'residual': residual,
               'captured': float(self.captured),
               'released': float(self.released)}
        # per part type: whole parts held by the macro scale (deposited, not yet released or
        # sunk) and the type ledger's residual (typed entries vs mass, see check_balance)
        held = self.types_held()
        for t, p in enumerate(self.cell.part_types):
            out[f'macro_{p.name}'] = float(held[t])
        out['type_residual'] = self._type_residual(held)
        return out

    def types_held(self) -> np.ndarray:
        """Return the whole parts per type held by the macro scale (all grids)."""
        held = np.zeros(self.n_types, dtype=np.int64)
        for r in self.regions:
            held += r.types_held(self.n_types)
        return held

    def _type_residual(self, held: np.ndarray) -> float:
        """Return ``typed entries - (mass + sink remainder) + inflow - untyped`` [parts].

        Every whole part deposited adds a typed FIFO entry; every part released or sunk
        removes one. So the entries held equal the mass in the grids and accumulators plus
        the fraction of a part that left through sinks but was not yet given a type, minus
        the mass of prescribed inflow, plus the releases that found the FIFO empty.
        """
        r = float(held.sum())
        for reg in self.regions:
            r -= reg.sim.total_parts() + sum(float(a.sum()) for a in reg.face_acc)
            r -= reg.left - reg.sink_popped
            r -= reg.vanished - reg.vanish_popped
            r += reg.sim.parts_in - float(reg.fstate[2])
        return r

    def check_balance(self) -> float:
        """Check the ledger; return the residual [parts].

        :raises BalanceError: if ``|residual|`` exceeds :data:`BALANCE_TOLERANCE`.
        """
        led = self.ledger()
        r = led['residual']
        self.max_residual = max(self.max_residual, abs(r), abs(led['type_residual']))
        if not (abs(r) <= BALANCE_TOLERANCE and abs(led['type_residual']) <= BALANCE_TOLERANCE):
            msg = f'part ledger off by {r:.3e} parts at step {self.step_index}: {led}'
            raise BalanceError(msg)
        return r

    def state_bytes(self) -> bytes:
        """Return the coupling's dynamic state (accumulators, masks, counters) as bytes."""
        parts = [np.array([self.left_macro, self.released, self.captured,
                           self.vanished_macro]).tobytes(),
                 self.captured_by_type.tobytes(), self.released_by_type.tobytes(),
                 self.left_by_type.tobytes()]
        for r in self.regions:
            parts += [r.active.tobytes(), r.rot.tobytes(), r.fstate.tobytes(),
                      r.types_held(self.n_types).tobytes(), r.rng.tobytes(),
                      r.thr.tobytes(),
                      np.array([r.left, r.sink_popped, r.vanished,
                                r.vanish_popped]).tobytes()]
            parts += [a.tobytes() for a in r.face_acc]
            if r.tiles is not None:
                parts += [r.tiles.macro.tobytes(), r.tiles.last_switch.tobytes()]
        for b in self.barriers:
            parts.append(np.array([b.crossings, b.travel, b.blocked, b.edge_count]).tobytes())
        return b''.join(parts)
