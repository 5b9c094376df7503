"""``MicroSim``: the micro simulator of one cell (or one region of it), stepped in compiled code.

Usage::

    sim = MicroSim(load_cell(None), seed=1)
    sim.set_belt_target(0, 0.8)
    sim.step(10)                       # one compiled call for all 10 steps
    parts = sim.parts_view()           # arrays of length n, ids ascending
    events = sim.drain_events()        # light-barrier edges since the last drain

Units are SI throughout. The part arrays are a structure of arrays with a fixed capacity
(``cell.micro.capacity``); parts keep the order they entered in (removal compacts), and ids
start at 1 and are never reused within a run. The same cell, seed and command sequence give
bit-identical states (:meth:`MicroSim.state_bytes`).
"""

import hashlib
import math
from typing import Dict, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell, ContactModel
from conveyor_twin.micro.actuators import actuator_arrays, actuator_shapes, actuator_table
from conveyor_twin.micro.contacts import (A_BELT, A_COLUMNS, A_CONTACT_FRICTION, A_DAMPER,
                                          A_INERTIA, A_SPRING, MODE_IMPULSE, MODE_PENALTY,
                                          MP_COLUMNS, MP_CORRECTION, MP_DAMPING, MP_DT,
                                          MP_BOUNCE_PASSES, MP_BOUNCE_TOLERANCE,
                                          MP_MAX_SWEEPS, MP_SPEC_MARGIN, MP_SPEC_MAX,
                                          MP_SWEEP_WORK, MP_TOLERANCE,
                                          MP_FLOOR_MU, MP_GRAVITY, MP_SLOP, MP_STIFFNESS, MP_TRACK,
                                          NB_BUILDS, grid_table, neighbour_arrays, scratch)
from conveyor_twin.micro.drive import FLOOR_FRICTION
from conveyor_twin.micro.errors import CapacityError, SpawnBoundsError, SpawnOverlapError
from conveyor_twin.micro.footprint import footprint_table
from conveyor_twin.micro.geometry import (build_grid, cell_extent, obstacle_shapes,
                                          outside_extent, world_bounds)
from conveyor_twin.micro.kernel import (AV_LIMIT, AV_LOAD, AV_POSITION, AV_PREVIOUS, AV_ROWS,
                                        AV_SUB, AV_TARGET,
                                        BV_LIMIT, BV_SPEED, BV_TARGET, CF_AUTO_SUB, CF_COLUMNS,
                                        CF_DT, CF_FLOOR_MU, CF_MAX_SUB, CF_MAX_TRAVEL, CF_MODE,
                                        CF_PASSES, CF_PENALTY_DT, CF_POSITION_PASSES, CF_SKIN,
                                        run_steps)
from conveyor_twin.micro.sensors import (barrier_table, EV_BARRIER, EV_BLOCKED, EV_FLOAT_COLUMNS,
                                         EV_FRACTION, EV_INT_COLUMNS, EV_PART, EV_STEP, EV_TIME)
from conveyor_twin.micro.sinks import OB_ROWS, remove_marked, RG_SIZE
from conveyor_twin.micro.sources import place, seed_streams, source_table, SS_COLUMNS
from conveyor_twin.micro.state import (C_CONTACTS_FULL, C_ENTERED, C_EVENTS,
                                       C_EVENTS_DROPPED, C_N, C_NEXT_ID, C_OUTBOX,
                                       C_REGION_LEFT, C_REMOVED, C_STEP, C_SUBSTEPS,
                                       C_SUBSTEPS_CAPPED, C_VANISHED, part_table, PartState,
                                       PartsView, PT_BRAD)
from conveyor_twin.micro.surfaces import belt_table, BT_DV, transfer_table

# Events buffer entries; edges beyond it between two drains are counted as dropped.
EVENT_CAPACITY = 4096
# Penalty model: largest omega * dt of the stiffest contact (symplectic Euler is stable < 2).
PENALTY_OMEGA_DT = 0.5
# Impulse model: the restitution sweeps (only the bouncing contacts; see contacts.restitution).
BOUNCE_PASSES = 64
BOUNCE_TOLERANCE = 1e-12
# Impulse model, speculative contacts: a pair is recorded while its gap is below the distance
# it may close in a substep plus SPECULATIVE_MARGIN, at most SPECULATIVE_MAX (fractions of the
# smallest part radius).
SPECULATIVE_MARGIN = 0.05
SPECULATIVE_MAX = 0.5
# Impulse model: sweeps of the penetration correction per substep (one keeps the benchmark jam's
# overlaps within 0.34 mm of 10 mm discs once formed; a second costs as much as a tenth of the
# step at N = 5000 and changes little).
POSITION_PASSES = 1
# Neighbour list skin as a fraction of the smallest part radius: a part may move 0.49 of it
# before the list is rebuilt (in a jam it lives for many steps; in free flow at 0.5 m/s with
# 10 mm discs and 1 ms steps it is rebuilt every fourth step). 0.8 against 0.4: the 1000-disc
# bench scene's approach to the jam (everything moving) 1.16x faster than without a list
# instead of 0.77x, the settled jam alike.
SKIN_FRACTION = 0.8
# Most substeps per step (impulse: travel; penalty: stability).
MAX_SUBSTEPS_IMPULSE = 64
MAX_SUBSTEPS_PENALTY = 1_000_000

Region = Tuple[float, float, float, float]


class EdgeEvents(NamedTuple):
    """Light-barrier edges, one entry per edge, in the order they were detected."""

    barrier: np.ndarray     # int64 index into cell.light_barriers
    blocked: np.ndarray     # bool: True when the beam became interrupted
    part_id: np.ndarray     # uint32 id of the part that caused it
    step: np.ndarray        # int64 step in which it happened
    fraction: np.ndarray    # float64 fraction of that step, in [0, 1]
    time: np.ndarray        # float64 sim time of the edge [s]

    def __len__(self) -> int:  # noqa: D105
        return int(self.barrier.size)


def smallest_radius(cell: Cell) -> float:
    """Return the smallest inscribed radius over the cell's part types [m]."""
    return min(p.radius if p.shape == 'disc' else 0.5 * min(p.length, p.width)
               for p in cell.part_types)


def penalty_substep(cell: Cell, stiffness: float, damping: float) -> float:
    """Return the largest stable substep [s] of the penalty model for the cell's parts.

    The stiffest contact is part on part of the lightest type (effective mass m/2):
    ``omega = sqrt(k / m_eff)``; with damping the damped frequency bound
    ``omega_c = omega (sqrt(1 + z^2) + z)``, ``z = c / (2 sqrt(k m_eff))``, is used.
    """
    m_eff = 0.5 * min(p.mass for p in cell.part_types)
    omega = math.sqrt(stiffness / m_eff)
    zeta = damping / (2.0 * math.sqrt(stiffness * m_eff))
    return PENALTY_OMEGA_DT / (omega * (math.sqrt(1.0 + zeta * zeta) + zeta))


class MicroSim:
    """The micro simulator of a cell.

    :param cell: the validated cell.
    :param seed: random seed of the sources (the run's seed).
    :param region: (x_min, y_min, x_max, y_max) [m] simulated here; parts whose centre leaves
        it go to the outbox (:meth:`drain_outbox`). ``None``: the whole cell.
    :param track_activity: accumulate the element activities (Rideout and Stein); default: for
        the penalty model.
    :param auto_substeps: choose substeps for travel and penalty stability; ``False`` takes
        exactly one substep per step (to measure raw step limits).
    :param event_capacity: size of the light-barrier events buffer.
    :param passes: impulse model: least sweeps over the contacts per substep; ``max_passes``
        the most, ``sweep_work`` the contact visits per substep that buy sweeps beyond
        ``passes`` (0: always ``passes``). ``None``: the cell's ``micro.contact_sweeps``,
        ``contact_sweeps_max``, ``contact_sweep_budget``. ``tolerance`` [m/s]: the sweeps stop
        once no contact's increment changes a relative speed by more (``None``: the cell's
        ``micro.contact_tolerance``; see :func:`~.contacts.impulses.solve_impulses`).
    :param position_passes: impulse model: sweeps of the penetration correction per substep
        (see :data:`POSITION_PASSES`).
    """

    def __init__(self, cell: Cell, *, seed: int, region: Optional[Region] = None,
                 track_activity: Optional[bool] = None, auto_substeps: bool = True,
                 event_capacity: int = EVENT_CAPACITY, passes: Optional[int] = None,
                 max_passes: Optional[int] = None, sweep_work: Optional[int] = None,
                 tolerance: Optional[float] = None,
                 position_passes: int = POSITION_PASSES) -> None:
        micro = cell.micro
        self.cell = cell
        self.seed = int(seed)
        self.dt = float(cell.settings.step)
        self.region = region
        self.contact = ContactModel(micro.contact)
        penalty = self.contact == ContactModel.PENALTY
        if track_activity is None:
            track_activity = penalty
        self.state = PartState(micro.capacity)
        self.pt = part_table(cell.part_types)
        r_min = smallest_radius(cell)
        max_brad = float(self.pt[:, PT_BRAD].max())
        self.mp = np.zeros(MP_COLUMNS)
        self.mp[MP_SLOP] = micro.penetration_slop
        self.mp[MP_CORRECTION] = micro.penetration_correction
        self.mp[MP_STIFFNESS] = micro.penalty_stiffness
        self.mp[MP_DAMPING] = micro.penalty_damping
        self.mp[MP_DT] = self.dt
        self.mp[MP_GRAVITY] = cell.settings.gravity
        self.mp[MP_FLOOR_MU] = FLOOR_FRICTION
        self.mp[MP_TRACK] = 1.0 if track_activity else 0.0
        if not penalty:
            self.mp[MP_SPEC_MARGIN] = SPECULATIVE_MARGIN * r_min
            self.mp[MP_SPEC_MAX] = SPECULATIVE_MAX * r_min
            self.mp[MP_TOLERANCE] = float(micro.contact_tolerance if tolerance is None
                                          else tolerance)
            self.mp[MP_BOUNCE_TOLERANCE] = BOUNCE_TOLERANCE
            self.mp[MP_BOUNCE_PASSES] = BOUNCE_PASSES
            self.mp[MP_SWEEP_WORK] = max(0, int(micro.contact_sweep_budget if sweep_work is None
                                                else sweep_work))
            self.mp[MP_MAX_SWEEPS] = max(1, int(micro.contact_sweeps_max if max_passes is None
                                                else max_passes))
        self.cfg = np.zeros(CF_COLUMNS)
        self.cfg[CF_DT] = self.dt
        self.cfg[CF_MODE] = MODE_PENALTY if penalty else MODE_IMPULSE
        self.cfg[CF_AUTO_SUB] = 1.0 if auto_substeps else 0.0
        self.cfg[CF_MAX_TRAVEL] = micro.max_travel_fraction * r_min
        self.cfg[CF_PENALTY_DT] = penalty_substep(cell, micro.penalty_stiffness,
                                                  micro.penalty_damping)
        self.cfg[CF_MAX_SUB] = MAX_SUBSTEPS_PENALTY if penalty else MAX_SUBSTEPS_IMPULSE
        self.cfg[CF_FLOOR_MU] = FLOOR_FRICTION
        self.cfg[CF_PASSES] = max(1, int(micro.contact_sweeps if passes is None else passes))
        self.cfg[CF_POSITION_PASSES] = max(1, int(position_passes))
        self.cfg[CF_SKIN] = SKIN_FRACTION * r_min
        # belts
        self.belts = belt_table(cell.belts, self.dt)
        self.belt_v = np.zeros((3, len(cell.belts)))
        self.belt_v[BV_TARGET] = [b.speed for b in cell.belts]
        self.belt_v[BV_SPEED] = self.belt_v[BV_TARGET]
        self.belt_v[BV_LIMIT] = self.belts[:, BT_DV]
        # actuators
        self.apar = actuator_table(cell.actuators)
        self.act_v = np.zeros((AV_ROWS, len(cell.actuators)))
        for row in (AV_TARGET, AV_POSITION, AV_PREVIOUS, AV_SUB):
            self.act_v[row] = [a.initial_position for a in cell.actuators]
        self.act_v[AV_LIMIT] = [a.max_speed * self.dt for a in cell.actuators]
        self.act_state, self.act_verts = actuator_arrays(len(cell.actuators))
        # what the surface lookup reads (drive.belt_drive)
        self.surfaces = (self.belts, transfer_table(cell.actuators), self.act_v[AV_SUB],
                         footprint_table())
        actuator_shapes(self.apar, self.act_v[AV_POSITION], self.act_v[AV_LIMIT] * 0.0,
                        self.act_state, self.act_verts)
        # obstacles and grid
        self.shapes, self.shape_verts, self.shape_owner = obstacle_shapes(cell.obstacles)
        bounds = world_bounds(cell, self.shapes, region)
        #: (x_min, y_min, x_max, y_max) [m] where :meth:`spawn` may place parts
        self.extent = cell_extent(cell, self.shapes)
        # cells and static lists grown by the neighbour list's skin (update_pairs)
        self.grid = build_grid(bounds, max_brad, self.cfg[CF_SKIN] + self.mp[MP_SPEC_MAX],
                               self.shapes)
        cap = self.state.capacity
        self._cell_table = grid_table(self.grid.cells)
        self._cell_items = np.zeros(cap, dtype=np.int64)
        self._part_cell = np.zeros(cap, dtype=np.int64)
        self._W = np.zeros((5, cap))
        (self._cand, self._va, self._vb, self._out, self._ct, self._cidx, self._prev,
         self._island, self._island_sums) = scratch(cap)
        self._nbr, self._pos0 = neighbour_arrays(cap)
        self.acc = np.zeros(A_COLUMNS)
        # sources, sinks, region
        self.src = source_table(cell, cell.sources)
        self.src_next = np.array([s.start_time for s in cell.sources], dtype=np.float64)
        self.src_state = np.zeros((len(cell.sources), SS_COLUMNS), dtype=np.int64)
        self.rng = seed_streams(self.seed, cell.sources)
        self.sinks = np.array([s.region for s in cell.sinks], dtype=np.float64).reshape(-1, 4)
        self.sink_count = np.zeros(len(cell.sinks), dtype=np.int64)
        #: Parts taken out by :meth:`delete` (counted as left in :meth:`counters`).
        self.deleted = 0
        self.region_array = np.zeros(RG_SIZE)
        if region is not None:
            self.region_array[:] = (1.0, *region)
        self._ob_id = np.zeros(cap, dtype=np.uint32)
        self._ob_type = np.zeros(cap, dtype=np.uint16)
        self._ob_P = np.zeros((OB_ROWS, cap))
        # light barriers
        self.lb = barrier_table(cell.light_barriers)
        nb = len(cell.light_barriers)
        self.blocked = np.zeros(nb, dtype=np.bool_)
        self.edge_count = np.zeros(nb, dtype=np.uint32)
        self.last_part = np.zeros(nb, dtype=np.uint32)
        self._ev_i = np.zeros((event_capacity, EV_INT_COLUMNS), dtype=np.int64)
        self._ev_f = np.zeros((event_capacity, EV_FLOAT_COLUMNS))
        s = self.state
        # the arrays of run_steps, grouped by concept (see its docstring)
        self._args = (
            (s.counters, s.ids, s.part_type, s.P, self._W),
            (self.pt, self.mp, self.cfg),
            (self.surfaces, self.belt_v, self.apar, self.act_v, self.act_state, self.act_verts),
            (self.grid.gpar, self.grid.gdim, self._cell_table, self._cell_items,
             self._part_cell, self._cand, self._nbr, self._pos0),
            (self.grid.static_start, self.grid.static_items, self.shapes, self.shape_verts),
            (self._va, self._vb, self._out, self._ct, self._cidx, self.acc, self._prev,
             self._island, self._island_sums),
            (self.src, self.src_next, self.src_state, self.rng),
            (self.sinks, self.sink_count, self.region_array, self._ob_id, self._ob_type,
             self._ob_P),
            (self.lb, self.blocked, self.edge_count, self.last_part, self._ev_i, self._ev_f))
        # what sources.place reads and writes
        self._placing = (s.counters, s.ids, s.part_type, s.P, self.pt, self.shapes,
                         self.shape_verts, self.act_state, self.act_verts, self._va, self._vb,
                         self._out)

    # --- time ---
    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps in one compiled call.

        Light-barrier events accumulate until :meth:`drain_events`; the outbox until
        :meth:`drain_outbox`.
        """
        run_steps(int(n), *self._args)

    @property
    def step_index(self) -> int:
        """Steps taken so far (the state is stamped ``step_index * dt``)."""
        return int(self.state.counters[C_STEP])

    @property
    def time(self) -> float:
        """Sim time of the current state [s]."""
        return self.step_index * self.dt

    @property
    def neighbour_builds(self) -> int:
        """Builds of the neighbour list so far (the broad phase's grid search)."""
        return int(self._nbr[NB_BUILDS])

    @property
    def substeps(self) -> int:
        """Substeps taken in the last step."""
        return int(self.state.counters[C_SUBSTEPS])

    # --- commands ---
    def set_belt_target(self, index: int, speed: float) -> None:
        """Set belt ``index``'s target speed [m/s]; the actual speed ramps at its acceleration.

        Feeding the coordinator's per-step actual speeds here reproduces them exactly (each is
        within one step's ramp of the last).
        """
        assert abs(speed) <= self.cell.belts[index].max_speed + 1e-12, (index, speed)
        self.belt_v[BV_TARGET, index] = speed

    def set_actuator_target(self, index: int, position: float) -> None:
        """Set actuator ``index``'s target position [m or rad]; it moves at its max speed."""
        low, high = self.cell.actuators[index].position_range
        assert low - 1e-12 <= position <= high + 1e-12, (index, position)
        self.act_v[AV_TARGET, index] = position

    def apply_actuation(self, belt_speed: np.ndarray, actuator_position: np.ndarray) -> None:
        """Take the coordinator's actual belt speeds [m/s] and actuator positions of the step.

        They become the targets; being within one step's ramp, they are reached exactly.
        """
        self.belt_v[BV_TARGET, :] = belt_speed
        self.act_v[AV_TARGET, :] = actuator_position

    @property
    def belt_target(self) -> np.ndarray:
        """Target speed of every belt [m/s] (view)."""
        return self.belt_v[BV_TARGET]

    @property
    def belt_speed(self) -> np.ndarray:
        """Actual speed of every belt [m/s] (view)."""
        return self.belt_v[BV_SPEED]

    @property
    def actuator_target(self) -> np.ndarray:
        """Target position of every actuator [m or rad] (view)."""
        return self.act_v[AV_TARGET]

    @property
    def actuator_position(self) -> np.ndarray:
        """Actual position of every actuator [m or rad] (view)."""
        return self.act_v[AV_POSITION]

    @property
    def actuator_load(self) -> np.ndarray:
        """Mean normal force the parts put on every actuator during the last step [N]
        (view; :mod:`conveyor_twin.micro.actuator_load`)."""
        return self.act_v[AV_LOAD]

    # --- parts ---
    @property
    def n(self) -> int:
        """Number of parts simulated here."""
        return self.state.n

    def parts_view(self) -> PartsView:
        """Return views of the active parts, ids ascending (valid until the next change)."""
        return self.state.view()

    def spawn(self, part_type: int, x, y, yaw, vx=0.0, vy=0.0, wz=0.0, *,
              strict: bool = True) -> np.ndarray:
        """Place parts of type index ``part_type`` at the given poses; return their ids.

        Arguments broadcast to a common length. Poses overlapping a part (also one placed
        earlier in the same call), an obstacle or a solid actuator are refused, and so are
        centres outside the cell's extent (:attr:`extent`: belts, sources, sinks, obstacles,
        actuators' reach and zones) or not finite, and non-finite yaw or velocities.

        :param x: [m]. :param y: [m]. :param yaw: [rad]. :param vx: [m/s]. :param wz: [rad/s].
        :param strict: ``True``: place all or nothing, raising :class:`SpawnBoundsError` or
            :class:`SpawnOverlapError` naming the refused indices; ``False``: refused entries
            get id 0.
        :return: uint32 ids.
        :raises CapacityError: when the capacity cannot hold them.
        """
        t = int(part_type)
        if not 0 <= t < len(self.cell.part_types):
            last = len(self.cell.part_types) - 1
            raise IndexError(f'part type index {t} outside 0..{last}')
        arrays = np.broadcast_arrays(*(np.atleast_1d(np.asarray(a, dtype=np.float64))
                                       for a in (x, y, yaw, vx, vy, wz)))
        count = arrays[0].size
        if self.n + count > self.state.capacity:
            msg = f'{count} parts do not fit: {self.n} of {self.state.capacity} slots used'
            raise CapacityError(msg)
        outside = self.outside(arrays[0], arrays[1])
        unfinite = np.flatnonzero(~np.isfinite(np.stack(arrays[2:])).all(axis=0))
        if strict and (outside.size or unfinite.size):
            raise SpawnBoundsError(self._bounds_message(t, arrays, outside, unfinite))
        s = self.state
        ids = np.zeros(count, dtype=np.uint32)
        skip = set(outside.tolist()) | set(unfinite.tolist())
        for k in range(count):
            if k in skip:
                continue
            px, py, pyaw, pvx, pvy, pwz = (float(a[k]) for a in arrays)
            ids[k] = place(t, px, py, _wrap(pyaw), pvx, pvy, pwz, self._placing)
        refused = np.flatnonzero(ids == 0)
        if strict and refused.size:
            placed = int(np.count_nonzero(ids))
            s.counters[C_N] -= placed
            s.counters[C_NEXT_ID] -= placed
            s.counters[C_ENTERED] -= placed
            msg = (f'spawn of {count} {self.cell.part_types[t].name!r} parts refused: '
                   f'entries {refused.tolist()[:20]} overlap a part, an obstacle or an '
                   'actuator; nothing placed')
            raise SpawnOverlapError(msg)
        return ids

    def outside(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Return the indices of centres (x, y) [m] outside :attr:`extent` or not finite."""
        return outside_extent(self.extent, np.asarray(x, dtype=np.float64),
                              np.asarray(y, dtype=np.float64))

    def _bounds_message(self, t: int, arrays, outside: np.ndarray,
                        unfinite: np.ndarray) -> str:
        x0, y0, x1, y1 = self.extent
        count = arrays[0].size
        parts = [f'spawn of {count} {self.cell.part_types[t].name!r} parts refused:']
        if outside.size:
            k = int(outside[0])
            parts.append(f'entries {outside.tolist()[:20]} lie outside the cell (e.g. entry '
                         f'{k} at x = {arrays[0][k]:g} m, y = {arrays[1][k]:g} m; the cell '
                         f'spans x {x0:g}..{x1:g} m, y {y0:g}..{y1:g} m)')
        if unfinite.size:
            parts.append(f'entries {unfinite.tolist()[:20]} have a yaw or velocity that is '
                         'not a finite number')
        return ' '.join(parts) + '; nothing placed'

    def place_one(self, part_type: int, x: float, y: float, yaw: float, vx: float, vy: float,
                  wz: float) -> int:
        """Place one part unless it overlaps anything or the capacity is full; return its id or 0.

        The scalar fast path of :meth:`spawn` (``strict=False``) for the scale hand-over.
        :param x: [m]. :param y: [m]. :param yaw: [rad]. :param vx: [m/s]. :param wz: [rad/s].
        """
        return int(place(int(part_type), float(x), float(y), _wrap(float(yaw)), float(vx),
                         float(vy), float(wz), self._placing))

    def remove(self, ids: Optional[Sequence[int]] = None, *,
               mask: Optional[np.ndarray] = None) -> PartsView:
        """Remove parts by id or by a bool mask over the active parts; return copies of them.

        The remaining parts keep their order. The removed parts (ids ascending) are what a
        coordinator hands over to another scale.
        """
        n = self.n
        if mask is None:
            mask = np.isin(self.state.ids[:n], np.asarray(ids if ids is not None else [],
                                                          dtype=np.uint32))
        mask = np.asarray(mask, dtype=np.bool_)
        if mask.shape != (n,):
            raise ValueError(f'mask of shape {mask.shape}, expected ({n},)')
        k = int(mask.sum())
        out_id = np.zeros(k, dtype=np.uint32)
        out_type = np.zeros(k, dtype=np.uint16)
        out_P = np.zeros((OB_ROWS, k))
        s = self.state
        remove_marked(s.counters, s.ids, s.part_type, s.P, mask, out_id, out_type, out_P)
        s.counters[C_REMOVED] += k
        return PartsView(out_id, out_type, *out_P)

    def vanish(self, mask: np.ndarray) -> int:
        """Remove the parts of a bool mask over the active parts as fallen off the line
        (counted in ``vanished``, not ``removed``); return how many."""
        view = self.remove(mask=mask)
        k = len(view.id)
        self.state.counters[C_REMOVED] -= k
        self.state.counters[C_VANISHED] += k
        return k

    def delete(self, ids: Sequence[int]) -> int:
        """Take parts out of the cell by id, as if they had left through a sink (a delete
        request): they count as ``left`` (and ``deleted``) in :meth:`counters`, not as
        ``removed``, so the part ledger stays balanced; return how many were deleted.

        :raises KeyError: naming the ids the cell does not hold now (nothing deleted).
        """
        wanted = np.unique(np.asarray(ids, dtype=np.uint32))
        held = self.state.ids[:self.n]
        missing = wanted[~np.isin(wanted, held)]
        if missing.size:
            raise KeyError(f'no part with id {missing.tolist()[:20]} in the micro scale; '
                           'nothing deleted')
        k = len(self.remove(wanted).id)
        self.state.counters[C_REMOVED] -= k
        self.deleted += k
        return k

    def drain_outbox(self) -> PartsView:
        """Return copies of the parts that left the region since the last drain; empty it."""
        m = int(self.state.counters[C_OUTBOX])
        view = PartsView(self._ob_id[:m].copy(), self._ob_type[:m].copy(),
                         *(row[:m].copy() for row in self._ob_P))
        self.state.counters[C_OUTBOX] = 0
        return view

    # --- counters ---
    @property
    def entered(self) -> int:
        """Parts that entered (sources and :meth:`spawn`)."""
        return int(self.state.counters[C_ENTERED])

    @property
    def left(self) -> np.ndarray:
        """Parts that left through each sink (int64 per sink, view)."""
        return self.sink_count

    @property
    def in_flight(self) -> int:
        """Parts simulated here now."""
        return self.n

    def counters(self) -> Dict[str, int]:
        """Return the part balance: entered = in_flight + left + handed_over + removed +
        vanished (``left``: through sinks, plus ``deleted``)."""
        c = self.state.counters
        return {'entered': int(c[C_ENTERED]),
                'left': int(self.sink_count.sum()) + self.deleted, 'deleted': self.deleted,
                'in_flight': self.n, 'handed_over': int(c[C_REGION_LEFT]),
                'removed': int(c[C_REMOVED]), 'vanished': int(c[C_VANISHED]),
                'substeps': int(c[C_SUBSTEPS]),
                'substeps_capped': int(c[C_SUBSTEPS_CAPPED]),
                'events_dropped': int(c[C_EVENTS_DROPPED]),
                'contacts_full': int(c[C_CONTACTS_FULL])}

    # --- light barriers ---
    @property
    def event_count(self) -> int:
        """Edge events waiting in the buffer."""
        return int(self.state.counters[C_EVENTS])

    def drain_events(self) -> EdgeEvents:
        """Return the edge events since the last drain (copies) and empty the buffer."""
        m = self.event_count
        ev_i = self._ev_i[:m]
        ev_f = self._ev_f[:m]
        events = EdgeEvents(ev_i[:, EV_BARRIER].copy(), ev_i[:, EV_BLOCKED] != 0,
                            ev_i[:, EV_PART].astype(np.uint32), ev_i[:, EV_STEP].copy(),
                            ev_f[:, EV_FRACTION].copy(), ev_f[:, EV_TIME].copy())
        self.state.counters[C_EVENTS] = 0
        return events

    # --- activity (Rideout and Stein) ---
    def activity(self) -> Dict[str, float]:
        """Return the activity ``integral |power| dt`` of each element class so far [J]."""
        a = self.acc
        return {'contact_springs': float(a[A_SPRING]), 'contact_dampers': float(a[A_DAMPER]),
                'contact_friction': float(a[A_CONTACT_FRICTION]),
                'belt_friction': float(a[A_BELT]), 'part_inertia': float(a[A_INERTIA])}

    # --- determinism ---
    def state_bytes(self) -> bytes:
        """Return the full dynamic state as bytes (parts, belts, actuators, sensors, sources)."""
        s = self.state
        n = s.n
        return b''.join((s.counters.tobytes(), s.ids[:n].tobytes(), s.part_type[:n].tobytes(),
                         np.ascontiguousarray(s.P[:, :n]).tobytes(), self.belt_v.tobytes(),
                         self.act_v[:AV_LOAD].tobytes(), self.blocked.tobytes(),
                         self.edge_count.tobytes(), self.src_next.tobytes(),
                         self.src_state.tobytes(), self.rng.tobytes(),
                         self.sink_count.tobytes(), self.acc.tobytes(),
                         # only after a delete: runs without one keep their bytes
                         np.int64(self.deleted).tobytes() if self.deleted else b''))

    def state_hash(self) -> str:
        """Return the SHA-256 hex digest of :meth:`state_bytes`."""
        return hashlib.sha256(self.state_bytes()).hexdigest()


def _wrap(angle: float) -> float:
    a = math.fmod(angle + math.pi, 2.0 * math.pi)
    if a <= 0.0:
        a += 2.0 * math.pi
    return a - math.pi
