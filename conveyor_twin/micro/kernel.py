"""The compiled step loop: one call advances any number of steps without returning to Python.

Each step (the state after step ``k`` is stamped ``k dt``):
1. belt speeds and actuator positions move toward their targets (rate limited);
2. sources release the parts due at the step's start;
3. the pose at the step's start is saved (for light-barrier interpolation);
4. ``m`` substeps of length ``dt / m``, each: actuator poses interpolated, belt friction on the
   velocities, broad phase (a neighbour list with a skin, rebuilt on a uniform grid when a part
   moved too far or parts came or went) and near phase (contact records, speculative ones for
   the impulse model), then either the impulses (velocity sweeps to a tolerance, then the
   restitution pass), positions ``x += h v`` (semi-implicit Euler) and the penetration
   correction, or the penalty forces (velocities) and ``x += h v``;
5. light barriers sampled, edges recorded;
6. parts in sinks or outside the region leave (arrays compacted, order kept).

``m`` is the least number of substeps keeping every part's travel per substep below
``max_travel_fraction`` of the smallest part radius (so no contact is missed, no tunnelling),
and, for the penalty model, the substep below its stability limit; capped at ``CF_MAX_SUB``.
"""

import math

from numba import njit

from conveyor_twin.micro.actuator_load import add_actuator_load
from conveyor_twin.micro.actuators import actuator_shapes, AP_LENGTH, AP_WIDTH
from conveyor_twin.micro.contacts.broad_phase import update_pairs
from conveyor_twin.micro.contacts.energy import limit_energy
from conveyor_twin.micro.contacts.impulses import (correct_positions, prepare_contacts,
                                                   solve_impulses)
from conveyor_twin.micro.contacts.narrow_phase import detect
from conveyor_twin.micro.contacts.penalty import penalty_forces
from conveyor_twin.micro.contacts.response import MODE_PENALTY
from conveyor_twin.micro.contacts.restitution import restitute
from conveyor_twin.micro.contacts.tables import A_INERTIA, MP_DT, MP_SPEC_MAX, MP_TRACK
from conveyor_twin.micro.drive import belt_drive, ramp
from conveyor_twin.micro.sensors import update_barriers
from conveyor_twin.micro.sinks import leave
from conveyor_twin.micro.sources import run_sources
from conveyor_twin.micro.state import (C_CONTACTS_FULL, C_N, C_STEP, C_SUBSTEPS, C_SUBSTEPS_CAPPED,
                                       P_VX, P_VY, P_WZ, P_X, P_X_PREV, P_Y, P_Y_PREV, P_YAW,
                                       P_YAW_PREV, PT_BRAD, PT_INV_INERTIA, PT_INV_MASS)

# --- configuration slots (float64 array ``cfg``) ---
CF_DT = 0             # step [s]
CF_MODE = 1           # contact model: 0 impulse, 1 penalty
CF_AUTO_SUB = 2       # 1: choose substeps (travel, penalty stability); 0: one per step
CF_MAX_TRAVEL = 3     # largest travel per substep [m]
CF_PENALTY_DT = 4     # largest stable penalty substep [s]
CF_MAX_SUB = 5        # most substeps per step
CF_FLOOR_MU = 6
CF_PASSES = 7         # impulse model: most impulse sweeps over the contacts
CF_SKIN = 8           # neighbour list skin [m] (see contacts.broad_phase.update_pairs)
CF_POSITION_PASSES = 9  # impulse model: sweeps of the penetration correction
CF_COLUMNS = 10

# --- rows of the belt array ``belt_v`` (3, B) ---
BV_TARGET = 0
BV_SPEED = 1
BV_LIMIT = 2          # largest change per step [m/s]

# --- rows of the actuator array ``act_v`` (AV_ROWS, A) ---
AV_TARGET = 0
AV_POSITION = 1       # at the end of the step
AV_PREVIOUS = 2       # at the start of the step
AV_RATE = 3           # during the step [m/s or rad/s]
AV_LIMIT = 4          # largest change per step
AV_SUB = 5            # at the current substep
AV_LOAD = 6           # mean normal force of the parts on it during the step [N]
AV_ROWS = 7


@njit(cache=True)
def _substeps(n, ptype, P, pt, apar, act_v, cfg):
    if cfg[CF_AUTO_SUB] == 0.0:
        return 1, False
    dt = cfg[CF_DT]
    fastest = 0.0
    for i in range(n):
        s = (math.sqrt(P[P_VX, i] ** 2 + P[P_VY, i] ** 2)
             + abs(P[P_WZ, i]) * pt[ptype[i], PT_BRAD])
        if s > fastest:
            fastest = s
    for a in range(apar.shape[0]):
        # a part hit by an actuator leaves at up to twice its surface speed
        reach = apar[a, AP_LENGTH] + apar[a, AP_WIDTH]
        s = 2.0 * abs(act_v[AV_RATE, a]) * max(reach, 1.0)
        if s > fastest:
            fastest = s
    m = 1
    if fastest > 0.0:
        m = max(1, int(math.ceil(fastest * dt / cfg[CF_MAX_TRAVEL])))
    if cfg[CF_MODE] == MODE_PENALTY:
        m = max(m, int(math.ceil(dt / cfg[CF_PENALTY_DT] - 1e-9)))
    limit = int(cfg[CF_MAX_SUB])
    if m > limit:
        return limit, True
    return m, False


@njit(cache=True)
def run_steps(nsteps, parts, model, drives, grid, statics, contacts, sources, exits, barriers):
    """Advance ``nsteps`` steps in place (see the module docstring for the arrays' meaning).

    The arrays come in tuples by concept (unpacked here, no copies; built by
    :class:`conveyor_twin.micro.sim.MicroSim`):

    :param parts: ``(counters, ids, ptype, P, W)``: the parts' state and work rows.
    :param model: ``(pt, mp, cfg)``: part types, contact model parameters, configuration.
    :param drives: ``(surfaces, belt_v, apar, act_v, act_state, act_verts)``: the surfaces
        (belts, transfer units, footprint: :func:`~conveyor_twin.micro.drive.belt_drive`),
        belts, actuators.
    :param grid: ``(gpar, gdim, cell_table, cell_items, part_cell, cand, nbr, pos0)``: the
        broad phase's grid and neighbour list.
    :param statics: ``(static_start, static_items, shp, shp_verts)``: static shapes per cell.
    :param contacts: ``(va, vb, out, ct, cidx, acc, prev, island, island_sums)``: narrow-phase
        scratch, contact records, activities, the previous substep's contacts (warm start) and
        the scratch of the energy limit (``island_sums`` also holds the impulse sweeps' marks).
    :param sources: ``(src, src_next, src_state, rng)``; ``exits``: ``(sinks, sink_count,
        region, ob_id, ob_type, ob_P)``; ``barriers``: ``(lb, blocked, edge_count, last_part,
        ev_i, ev_f)``.
    """
    counters, ids, ptype, P, W = parts
    pt, mp, cfg = model
    surfaces, belt_v, apar, act_v, act_state, act_verts = drives
    gpar, gdim, cell_table, cell_items, part_cell, cand, nbr, pos0 = grid
    static_start, static_items, shp, shp_verts = statics
    va, vb, out, ct, cidx, acc, prev, island, island_sums = contacts
    sinks, sink_count, region, ob_id, ob_type, ob_P = exits
    lb, blocked, edge_count, last_part, ev_i, ev_f = barriers
    # what a placement reads and writes (sources.place)
    micro = (counters, ids, ptype, P, pt, shp, shp_verts, act_state, act_verts, va, vb, out)
    dt = cfg[CF_DT]
    mode = int(cfg[CF_MODE])
    impulse = mode != MODE_PENALTY
    track = mp[MP_TRACK] != 0.0
    x = P[P_X]
    y = P[P_Y]
    yaw = P[P_YAW]
    vx = P[P_VX]
    vy = P[P_VY]
    wz = P[P_WZ]
    fx = W[0]
    fy = W[1]
    tz = W[2]
    ke = W[3]
    heat = W[4]
    na = apar.shape[0]
    passes = int(cfg[CF_PASSES])
    position_passes = int(cfg[CF_POSITION_PASSES])
    skin = cfg[CF_SKIN]
    act_load = act_v[AV_LOAD]
    n_static = shp.shape[0]
    inv_dt = 1.0 / dt
    for _ in range(nsteps):
        step = counters[C_STEP] + 1
        # 1. actuation
        ramp(belt_v[BV_SPEED], belt_v[BV_TARGET], belt_v[BV_LIMIT])
        for a in range(na):
            act_v[AV_PREVIOUS, a] = act_v[AV_POSITION, a]
            act_v[AV_LOAD, a] = 0.0
        ramp(act_v[AV_POSITION], act_v[AV_TARGET], act_v[AV_LIMIT])
        for a in range(na):
            act_v[AV_RATE, a] = (act_v[AV_POSITION, a] - act_v[AV_PREVIOUS, a]) / dt
        # 2. sources, against the actuators where they start the step
        actuator_shapes(apar, act_v[AV_PREVIOUS], act_v[AV_RATE], act_state, act_verts)
        run_sources((step - 1) * dt, sources, surfaces, belt_v[BV_SPEED], cfg[CF_FLOOR_MU],
                    micro)
        n = counters[C_N]
        # 3. pose at the step's start
        for i in range(n):
            P[P_X_PREV, i] = x[i]
            P[P_Y_PREV, i] = y[i]
            P[P_YAW_PREV, i] = yaw[i]
        # 4. substeps
        m, capped = _substeps(n, ptype, P, pt, apar, act_v, cfg)
        if capped:
            counters[C_SUBSTEPS_CAPPED] += 1
        counters[C_SUBSTEPS] = m
        h = dt / m
        mp[MP_DT] = h
        for s in range(m):
            f = (s + 1.0) / m
            for a in range(na):
                act_v[AV_SUB, a] = (act_v[AV_PREVIOUS, a]
                                    + f * (act_v[AV_POSITION, a] - act_v[AV_PREVIOUS, a]))
            actuator_shapes(apar, act_v[AV_SUB], act_v[AV_RATE], act_state, act_verts)
            if track:
                for i in range(n):
                    t = ptype[i]
                    ke[i] = 0.5 * ((vx[i] * vx[i] + vy[i] * vy[i]) / pt[t, PT_INV_MASS]
                                   + wz[i] * wz[i] / pt[t, PT_INV_INERTIA])
            belt_drive(n, ptype, x, y, vx, vy, wz, pt, surfaces, belt_v[BV_SPEED], mp, acc, heat)
            if mode == MODE_PENALTY:
                for i in range(n):
                    fx[i] = 0.0
                    fy[i] = 0.0
                    tz[i] = 0.0
            if update_pairs(n, ids, ptype, x, y, pt, gpar, gdim, cell_table, cell_items,
                            part_cell, cand, nbr, pos0, (skin, mp[MP_SPEC_MAX])) == 2:
                counters[C_CONTACTS_FULL] += 1
            nc = detect(n, parts, pt, grid, statics, drives, contacts, mp)
            if nc == ct.shape[0]:
                counters[C_CONTACTS_FULL] += 1
            if mode == MODE_PENALTY:
                penalty_forces(nc, ct, cidx, ptype, vx, vy, wz, fx, fy, tz, pt, mp, acc)
                add_actuator_load(nc, ct, cidx, n_static, (vx, vy, wz), mp, h, inv_dt, True,
                                  act_load)
                for i in range(n):
                    t = ptype[i]
                    vx[i] += h * fx[i] * pt[t, PT_INV_MASS]
                    vy[i] += h * fy[i] * pt[t, PT_INV_MASS]
                    wz[i] += h * tz[i] * pt[t, PT_INV_INERTIA]
            else:
                for i in range(n):
                    fx[i] = vx[i]     # velocities before the impulses, for limit_energy
                    fy[i] = vy[i]
                    tz[i] = wz[i]
                _found, bounces = prepare_contacts(nc, ct, cidx, ptype, pt, mp, vx, vy, wz,
                                                   fx, fy, tz, prev)
                solve_impulses(nc, ct, cidx, ptype, vx, vy, wz, pt, passes, mp, acc, prev,
                               island_sums)
                if bounces:
                    restitute(nc, ct, cidx, ptype, vx, vy, wz, pt, mp, island, prev)
                add_actuator_load(nc, ct, cidx, n_static, (vx, vy, wz), mp, h, inv_dt, False,
                                  act_load)
                limit_energy(n, nc, ptype, pt, (vx, vy, wz), (fx, fy, tz), heat, contacts)
            for i in range(n):
                if impulse:
                    fx[i] = x[i]      # positions at detection, for correct_positions
                    fy[i] = y[i]
                x[i] += h * vx[i]
                y[i] += h * vy[i]
                a = yaw[i] + h * wz[i]
                if a > math.pi:
                    a -= 2.0 * math.pi
                elif a <= -math.pi:
                    a += 2.0 * math.pi
                yaw[i] = a
            if impulse:
                # fx, fy hold the positions at detection
                correct_positions(nc, ct, cidx, ptype, x, y, fx, fy, pt, position_passes, mp)
            if track:
                for i in range(n):
                    t = ptype[i]
                    k1 = 0.5 * ((vx[i] * vx[i] + vy[i] * vy[i]) / pt[t, PT_INV_MASS]
                                + wz[i] * wz[i] / pt[t, PT_INV_INERTIA])
                    acc[A_INERTIA] += abs(k1 - ke[i])
        # 5. light barriers
        update_barriers(n, ids, ptype, P, pt, lb, blocked, edge_count, last_part, ev_i, ev_f,
                        counters, step, dt)
        # 6. leaving parts
        leave(counters, ids, ptype, P, sinks, sink_count, region, ob_id, ob_type, ob_P)
        counters[C_STEP] = step
