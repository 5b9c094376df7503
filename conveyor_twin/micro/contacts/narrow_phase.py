"""Narrow phase: the contact records (normal, points, depth, materials) of touching bodies.

:func:`detect` walks the broad phase's neighbour list (part pairs), then every part against the
static shapes of its grid cell and the active actuators, and writes one record per contact
point (columns ``CT_*`` of :mod:`.tables`) in the canonical order: all part pairs (i, j),
i < j, lexicographically, then every part against the static shapes (ascending index) and then
the actuators.

Speculative contacts (Catto): bodies apart by a gap smaller than the distance they may close
in the substep are recorded too, with the depth ``-gap``, so the impulses can stop them exactly
where they meet instead of after they overlap. A pair's margin is ``h (s_a + s_b) +
mp[MP_SPEC_MARGIN]``, at most ``mp[MP_SPEC_MAX]`` (``h`` the substep, ``s`` a bound of the
speed of any point of the body: ``|v_x| + |v_y| + |w| r``), so a fast pair is caught a substep
before it meets and a slow one costs nothing; the broad phase lists pairs within
``mp[MP_SPEC_MAX]`` more than their skin. The shapes are swept by half the margin each (the
midway points stay those of the bare shapes). :mod:`conveyor_twin.micro.reference` does the
same in plain Python. The geometry of each shape pair (discs, capsules, rounded polygons) is in
:mod:`conveyor_twin.micro.collide`.
"""

import math

from numba import njit
import numpy as np

from conveyor_twin.micro.collide import box_vertices, circle_circle, collide
from conveyor_twin.micro.contacts.broad_phase import NB_HEADER
from conveyor_twin.micro.contacts.tables import (AS_ACTIVE, AS_E, AS_MU, AS_NV, AS_PX, AS_PY,
                                                 AS_R, AS_VX, AS_VY, AS_W, AS_XMAX, AS_XMIN,
                                                 AS_YMAX, AS_YMIN, CONTACTS_PER_PART, CT_BVX,
                                                 CT_BVY, CT_BW, CT_COLUMNS, CT_DEPTH, CT_E,
                                                 CT_KA, CT_KB, CT_LN, CT_LT, PV_COLUMNS,
                                                 CT_MU_K, CT_MU_S, CT_NX, CT_NY, CT_RAX, CT_RAY,
                                                 CT_RBX, CT_RBY, CT_V_T, MP_DT,
                                                 MP_SPEC_MARGIN, MP_SPEC_MAX, SH_E, SH_MU, SH_NV,
                                                 SH_OFF, SH_R, SH_XMAX, SH_XMIN, SH_YMAX,
                                                 SH_YMIN)
from conveyor_twin.micro.state import (P_VX, P_VY, P_WZ, P_X, P_Y, P_YAW, PT_BRAD, PT_E, PT_HL,
                                       PT_HW, PT_MU_K, PT_MU_S, PT_RADIUS, PT_SHAPE, PT_V_T,
                                       SHAPE_DISC)

# Added to the first key of a part's contacts with fixed and kinematic bodies: they follow all
# part pairs in the canonical order (ids stay below it).
KEY_FIXED = 2.0 ** 40


@njit(cache=True)
def part_shape(pt, t, x, y, yaw, verts):
    """Fill ``verts`` with the core of a part; return (number of vertices, radius [m])."""
    if pt[t, PT_SHAPE] == SHAPE_DISC:
        verts[0, 0] = x
        verts[0, 1] = y
        return 1, pt[t, PT_RADIUS]
    box_vertices(x, y, yaw, pt[t, PT_HL], pt[t, PT_HW], verts)
    return 4, 0.0


@njit(cache=True, inline='always')
def _record(nc, ct, cidx, a, b, point, centres, normal, depth, material, motion, keys):
    """Write contact record ``nc`` of bodies ``a``, ``b`` (-1: fixed or kinematic).

    ``point = (px, py)`` [m]; ``centres = (ax, ay, bx, by)`` [m], the bodies' centres (or
    pivots); ``normal = (nx, ny)`` pointing to A; ``depth`` [m]; ``material = (e, mu_s, mu_k,
    v_t)``; ``motion = (bvx, bvy, bw)``, B's velocity if kinematic; ``keys = (ka, kb)``.
    """
    px, py = point
    ax, ay, bx, by = centres
    nx, ny = normal
    e, mu_s, mu_k, v_t = material
    bvx, bvy, bw = motion
    ka, kb = keys
    ct[nc, CT_KA] = ka
    ct[nc, CT_KB] = kb
    ct[nc, CT_LN] = 0.0
    ct[nc, CT_LT] = 0.0
    ct[nc, CT_NX] = nx
    ct[nc, CT_NY] = ny
    ct[nc, CT_RAX] = px - ax
    ct[nc, CT_RAY] = py - ay
    ct[nc, CT_RBX] = px - bx
    ct[nc, CT_RBY] = py - by
    ct[nc, CT_DEPTH] = depth
    ct[nc, CT_E] = e
    ct[nc, CT_MU_S] = mu_s
    ct[nc, CT_MU_K] = mu_k
    ct[nc, CT_V_T] = v_t
    ct[nc, CT_BVX] = bvx
    ct[nc, CT_BVY] = bvy
    ct[nc, CT_BW] = bw
    cidx[nc, 0] = a
    cidx[nc, 1] = b


@njit(cache=True, inline='always')
def _impact(dx, dy, ux, uy, radii, normal, depth, point):
    """Return a speculative disc-disc contact's ``(nx, ny, depth, px, py)``.

    Where the discs (``(dx, dy)`` from B's centre to A's, relative velocity ``(ux, uy)``
    [m/s], ``radii = (ra, rb)``) meet on their current paths: the normal at that instant, the
    depth ``-gap`` the sweeps let close along it (``u_n t``, ``t`` the time to touch: an
    impulse only if ``t`` is within the substep) and the point midway between where each
    disc's surface meets the other's, relative to B's centre (one point for both bodies, so
    the impulses keep angular momentum). Where they separate or pass each other, or approach
    so slowly that ``|u|^2`` underflows to 0: ``normal`` (the line of centres),
    ``depth`` and ``point`` unchanged.

    The normal at the meeting makes an impact that is resolved before the discs touch leave
    them as if they had touched (an oblique impact's angle stays that of touching discs).
    """
    ra, rb = radii
    b = dx * ux + dy * uy
    a = ux * ux + uy * uy
    rsum = ra + rb
    disc = b * b - a * (dx * dx + dy * dy - rsum * rsum)
    # a == 0 and b < 0: an approach below ~1e-162 m/s whose square underflowed (what a long
    # geometric decay, as in a jam, leaves of a speed); within a substep the discs move less
    # than 1e-160 m, so the line of centres is their normal and the gap their depth, as given
    if b >= 0.0 or disc < 0.0 or a == 0.0:
        return normal[0], normal[1], depth, point[0], point[1]
    t = (-b - math.sqrt(disc)) / a
    nx = (dx + ux * t) / rsum
    ny = (dy + uy * t) / rsum
    # A's surface point dx - ra n and B's rb n, relative to B's centre
    return (nx, ny, (nx * ux + ny * uy) * t, 0.5 * (dx + (rb - ra) * nx),
            0.5 * (dy + (rb - ra) * ny))


@njit(cache=True)
def _pair(i, j, keys, ptype, x, y, yaw, pt, va, vb, out, nc, ct, cidx, margin):
    """Record the contacts of parts i and j closer than ``margin`` [m]; return the new count.

    ``keys = (ka, kb)``: the first contact's keys."""
    ka, kb = keys
    ti = ptype[i]
    tj = ptype[j]
    half = 0.5 * margin
    if pt[ti, PT_SHAPE] == SHAPE_DISC and pt[tj, PT_SHAPE] == SHAPE_DISC:
        count = circle_circle(x[i], y[i], pt[ti, PT_RADIUS] + half, x[j], y[j],
                              pt[tj, PT_RADIUS] + half, out)
    else:
        na, ra = part_shape(pt, ti, x[i], y[i], yaw[i], va)
        nb, rb = part_shape(pt, tj, x[j], y[j], yaw[j], vb)
        count = collide(va, na, ra + half, vb, nb, rb + half, out)
    if count == 0:
        return nc
    e = 0.5 * (pt[ti, PT_E] + pt[tj, PT_E])
    mu_s = 0.5 * (pt[ti, PT_MU_S] + pt[tj, PT_MU_S])
    mu_k = 0.5 * (pt[ti, PT_MU_K] + pt[tj, PT_MU_K])
    v_t = 0.5 * (pt[ti, PT_V_T] + pt[tj, PT_V_T])
    for c in range(count):
        if nc >= ct.shape[0]:
            return nc
        _record(nc, ct, cidx, i, j, (out[2 + 3 * c], out[3 + 3 * c]), (x[i], y[i], x[j], y[j]),
                (out[0], out[1]), out[4 + 3 * c] - margin, (e, mu_s, mu_k, v_t),
                (0.0, 0.0, 0.0), (ka, kb + c))
        nc += 1
    return nc


@njit(cache=True)
def _fixed(i, keys, ptype, x, y, yaw, pt, va, body, out, nc, ct, cidx, margin):
    """Record the contacts of part i with a fixed or kinematic body closer than ``margin``
    [m]; return the new count.

    ``keys = (ka, kb)``: the first contact's keys; ``body = (vb, nb, rb, bvx, bvy, bw, bpx, bpy,
    e, mu)``: its core ``vb[:nb]`` and radius [m], velocity [m/s, rad/s] about the point
    ``(bpx, bpy)`` [m], restitution and friction.
    """
    ka, kb = keys
    vb, nb, rb, bvx, bvy, bw, bpx, bpy, e, mu = body
    ti = ptype[i]
    na, ra = part_shape(pt, ti, x[i], y[i], yaw[i], va)
    half = 0.5 * margin
    count = collide(va, na, ra + half, vb, nb, rb + half, out)
    if count == 0:
        return nc
    # the obstacle's friction is the sliding value; the part's static/sliding ratio the static
    ratio = pt[ti, PT_MU_S] / pt[ti, PT_MU_K] if pt[ti, PT_MU_K] > 0.0 else 1.0
    for c in range(count):
        if nc >= ct.shape[0]:
            return nc
        _record(nc, ct, cidx, i, -1, (out[2 + 3 * c], out[3 + 3 * c]), (x[i], y[i], bpx, bpy),
                (out[0], out[1]), out[4 + 3 * c] - margin,
                (e, mu * ratio, mu, pt[ti, PT_V_T]), (bvx, bvy, bw), (ka, kb + c))
        nc += 1
    return nc


@njit(cache=True)
def detect(n, parts, pt, grid, statics, drives, contacts, mp):
    """Record every contact of parts 0..n-1 in the canonical order; return how many.

    The arrays come in the groups of :func:`conveyor_twin.micro.kernel.run_steps` (unpacked
    here, no copies); read here:

    :param parts: ``ids`` (ascending: with the shape index or the point they key the records,
        ``CT_KA``, ``CT_KB``, ascending in the canonical order), ``ptype`` and the poses ``P``.
    :param grid: the neighbour list ``nbr`` and the parts' grid cells ``part_cell`` as
        :func:`update_pairs` left them (current for these positions).
    :param statics: ``(static_start, static_items, shp, shp_verts)``: the static shapes of each
        cell (int64[cells + 1], items), the shape table (S, SH_COLUMNS), their cores (V, 2) [m].
    :param drives: the actuator table ``act_state`` (A, AS_COLUMNS) and cores ``act_verts``
        (A, 4, 2).
    :param contacts: scratch ``va``, ``vb`` (4, 2) and ``out`` float64[8]; the output ``ct``
        (C, CT_COLUMNS), the contact records, and ``cidx`` (C, 2), their bodies. When full,
        further contacts are dropped (the caller sizes it; see ``contacts_full``).
    :param mp: the model parameters: the substep ``MP_DT`` and the speculative margins
        ``MP_SPEC_MARGIN``, ``MP_SPEC_MAX`` (see the module docstring).
    """
    _counters, ids, ptype, P, _W = parts
    _gpar, _gdim, _cell_table, _cell_items, part_cell, _cand, nbr, _pos0 = grid
    static_start, static_items, shp, shp_verts = statics
    _belts, _belt_v, _apar, _act_v, act_state, act_verts = drives
    va, vb, out, ct, cidx, _acc, _prev, _island, _island_sums = contacts
    x = P[P_X]
    y = P[P_Y]
    yaw = P[P_YAW]
    vx = P[P_VX]
    vy = P[P_VY]
    wz = P[P_WZ]
    h = mp[MP_DT]
    spec = mp[MP_SPEC_MARGIN]
    spec_max = mp[MP_SPEC_MAX]
    cap = part_cell.shape[0]
    o_start = NB_HEADER + cap
    o_j = o_start + cap + 1
    nc = 0
    n_static = shp.shape[0]
    for i in range(n):
        bri = pt[ptype[i], PT_BRAD]
        ka = float(ids[i])
        xi = x[i]
        yi = y[i]
        ti = ptype[i]
        disc_i = pt[ti, PT_SHAPE] == SHAPE_DISC
        si = spec + h * (abs(vx[i]) + abs(vy[i]) + abs(wz[i]) * bri)
        for p in range(nbr[o_start + i], nbr[o_start + i + 1]):
            j = nbr[o_j + p]
            tj = ptype[j]
            dx = x[j] - xi
            dy = y[j] - yi
            brj = pt[tj, PT_BRAD]
            margin = min(si + h * (abs(vx[j]) + abs(vy[j]) + abs(wz[j]) * brj), spec_max)
            rr = bri + brj + margin
            if dx * dx + dy * dy >= rr * rr:
                continue  # listed within the skin, not within the bounding radii
            if disc_i and pt[tj, PT_SHAPE] == SHAPE_DISC:
                # disc-disc, the common case, written out (same arithmetic as circle_circle)
                dx = xi - x[j]
                dy = yi - y[j]
                rsum = pt[ti, PT_RADIUS] + pt[tj, PT_RADIUS]
                d2 = dx * dx + dy * dy
                reach = rsum + margin
                if d2 >= reach * reach or nc >= ct.shape[0]:
                    continue
                d = math.sqrt(d2)
                if d > 0.0:
                    nx = dx / d
                    ny = dy / d
                else:
                    nx = 1.0
                    ny = 0.0
                depth = rsum - d
                rb = pt[tj, PT_RADIUS] - 0.5 * depth
                px = nx * rb
                py = ny * rb
                if depth < 0.0:
                    nx, ny, depth, px, py = _impact(dx, dy, vx[i] - vx[j], vy[i] - vy[j],
                                                    (pt[ti, PT_RADIUS], pt[tj, PT_RADIUS]),
                                                    (nx, ny), depth, (px, py))
                _record(nc, ct, cidx, i, j, (x[j] + px, y[j] + py),
                        (xi, yi, x[j], y[j]), (nx, ny), depth,
                        (0.5 * (pt[ti, PT_E] + pt[tj, PT_E]),
                         0.5 * (pt[ti, PT_MU_S] + pt[tj, PT_MU_S]),
                         0.5 * (pt[ti, PT_MU_K] + pt[tj, PT_MU_K]),
                         0.5 * (pt[ti, PT_V_T] + pt[tj, PT_V_T])), (0.0, 0.0, 0.0),
                        (ka, 2.0 * ids[j]))
                nc += 1
            else:
                nc = _pair(i, j, (ka, 2.0 * ids[j]), ptype, x, y, yaw, pt, va, vb, out, nc,
                           ct, cidx, margin)
    for i in range(n):
        bri = pt[ptype[i], PT_BRAD]
        ka = KEY_FIXED + ids[i]
        c = part_cell[i]
        si = spec + h * (abs(vx[i]) + abs(vy[i]) + abs(wz[i]) * bri)
        margin = min(si, spec_max)
        reach = bri + margin
        for k in range(static_start[c], static_start[c + 1]):
            s = static_items[k]
            if (x[i] + reach <= shp[s, SH_XMIN] or x[i] - reach >= shp[s, SH_XMAX]
                    or y[i] + reach <= shp[s, SH_YMIN] or y[i] - reach >= shp[s, SH_YMAX]):
                continue
            off = int(shp[s, SH_OFF])
            nv = int(shp[s, SH_NV])
            if nv == 2 and pt[ptype[i], PT_SHAPE] == SHAPE_DISC:
                # disc-capsule, the common case, written out (as circle_segment)
                ax = shp_verts[off, 0]
                ay = shp_verts[off, 1]
                ex = shp_verts[off + 1, 0] - ax
                ey = shp_verts[off + 1, 1] - ay
                l2 = ex * ex + ey * ey
                f = 0.0
                if l2 > 0.0:
                    f = min(max(((x[i] - ax) * ex + (y[i] - ay) * ey) / l2, 0.0), 1.0)
                qx = ax + f * ex
                qy = ay + f * ey
                dx = x[i] - qx
                dy = y[i] - qy
                rb = shp[s, SH_R]
                rsum = pt[ptype[i], PT_RADIUS] + rb
                d2 = dx * dx + dy * dy
                if d2 >= (rsum + margin) ** 2 or nc >= ct.shape[0]:
                    continue
                d = math.sqrt(d2)
                if d > 0.0:
                    nx = dx / d
                    ny = dy / d
                elif l2 > 0.0:
                    nx = ey / math.sqrt(l2)
                    ny = -ex / math.sqrt(l2)
                else:
                    nx = 1.0
                    ny = 0.0
                depth = rsum - d
                ti = ptype[i]
                mu = shp[s, SH_MU]
                ratio = pt[ti, PT_MU_S] / pt[ti, PT_MU_K] if pt[ti, PT_MU_K] > 0.0 else 1.0
                _record(nc, ct, cidx, i, -1,
                        (qx + nx * (rb - 0.5 * depth), qy + ny * (rb - 0.5 * depth)),
                        (x[i], y[i], 0.0, 0.0), (nx, ny), depth,
                        (shp[s, SH_E], mu * ratio, mu, pt[ti, PT_V_T]), (0.0, 0.0, 0.0),
                        (ka, 2.0 * s))
                nc += 1
                continue
            nc = _fixed(i, (ka, 2.0 * s), ptype, x, y, yaw, pt, va,
                        (shp_verts[off:off + nv], nv, shp[s, SH_R], 0.0, 0.0, 0.0, 0.0, 0.0,
                         shp[s, SH_E], shp[s, SH_MU]), out, nc, ct, cidx, margin)
        for a in range(act_state.shape[0]):
            if act_state[a, AS_ACTIVE] == 0.0:
                continue
            # the actuator's travel in the substep: its speed at the farthest corner
            xmin = act_state[a, AS_XMIN]
            xmax = act_state[a, AS_XMAX]
            ymin = act_state[a, AS_YMIN]
            ymax = act_state[a, AS_YMAX]
            px = act_state[a, AS_PX]
            py = act_state[a, AS_PY]
            arm = max(abs(xmax - px), abs(xmin - px)) + max(abs(ymax - py), abs(ymin - py))
            am = min(si + h * (abs(act_state[a, AS_VX]) + abs(act_state[a, AS_VY])
                               + abs(act_state[a, AS_W]) * arm), spec_max)
            ra = bri + am
            if x[i] + ra <= xmin or x[i] - ra >= xmax or y[i] + ra <= ymin or y[i] - ra >= ymax:
                continue
            nc = _fixed(i, (ka, 2.0 * (n_static + a)), ptype, x, y, yaw, pt, va,
                        (act_verts[a], int(act_state[a, AS_NV]), act_state[a, AS_R],
                         act_state[a, AS_VX], act_state[a, AS_VY], act_state[a, AS_W],
                         px, py, act_state[a, AS_E], act_state[a, AS_MU]), out, nc, ct, cidx,
                        am)
    return nc


def scratch(capacity: int):
    """Return the arrays of the contact kernels: (cand, va, vb, out, ct, cidx, prev, parent,
    acc3).

    ``prev`` (C + 1, PV_COLUMNS) keeps the previous substep's keys and impulses (row C: their
    count) for the warm start in :func:`conveyor_twin.micro.contacts.impulses.prepare_contacts`;
    ``parent`` (int64, capacity) and ``acc3`` ((3, capacity)) are the scratch of
    :func:`conveyor_twin.micro.contacts.energy.limit_energy`.
    """
    size = CONTACTS_PER_PART * capacity
    return (np.zeros(capacity + 1, dtype=np.int64), np.zeros((4, 2)), np.zeros((4, 2)),
            np.zeros(8), np.zeros((size, CT_COLUMNS)), np.zeros((size, 2), dtype=np.int64),
            np.zeros((size + 1, PV_COLUMNS)), np.zeros(capacity, dtype=np.int64),
            np.zeros((3, capacity)))
