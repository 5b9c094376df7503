"""Contact response kernels: impulses (Hoher et al.) or penalty spring-dampers (Rideout, Stein).

Impulse model: one algebraic impulse per contact point, no iteration. With the relative
velocity ``u`` of A against B at the contact and the unit normal ``n`` pointing to A:
``j = -(1 + e) u_n / (1/m_a + 1/m_b + (r_a x n)^2 / I_a + (r_b x n)^2 / I_b)`` when ``u_n < 0``;
then a tangential impulse that would stop the sliding, clamped to ``mu(|u_t|) j`` (Coulomb,
Horváth et al.'s speed-dependent coefficient: static at rest, sliding above the transition speed,
linear in between). Restitution acts only above :data:`RESTITUTION_THRESHOLD` so resting
contacts (a part pressed on a wall by the belt) do not chatter. Overlap beyond the slop is
removed by moving the bodies apart along ``n`` (in inverse-mass proportion) every substep.

Penalty model: a spring-damper per contact point, ``f_n = max(0, k d - c u_n)``, and a Coulomb
friction force ``min(mu f_n, |u_t| / (k_t dt))`` against the sliding (the second term stops it
within one substep without reversing it); no position correction.

Why two sweeps in the impulse model (``CONTACT_PASSES = 2`` in :mod:`.sim`), although Hoher et al.
solves each contact once: every contact is still one algebraic equation, solved a fixed number
of times per substep (no iteration to a tolerance, so cost and result stay time-deterministic),
but a single sweep does not hold a jam. The second sweep is a plastic shock-propagation sweep
(the downstream body of a pair counts as fixed) over the same contacts, and the position
correction does the same. Measured on the benchmark jam (``conveyor-twin bench micro`` scene,
4 s, checked every 0.1 s): with one sweep the deepest disc overlap reaches 9.7 mm (N = 300),
10.0 mm (N = 1000) and 9.99 mm (N = 5000) for 10 mm discs, i.e. parts pass through each other
under the belt's push (each substep's correction of 80 % of a contact's excess is undone by the
next rows pushing); with two sweeps it stays at 0.24, 0.24 and 0.93 mm. So the second sweep
stays; "penetration resolved every step" needs it once contacts share bodies.

The broad phase is a neighbour list with a skin (:func:`update_pairs`), searched on a uniform
grid only when a part moved more than half the skin or parts came or went; it gives exactly the
contacts of a fresh search, so results do not depend on when it was rebuilt.

Pairs are resolved in a canonical order whatever the broad phase: all part pairs (i, j), i < j,
lexicographically, then every part against the static shapes (ascending index) and then the
actuators. :mod:`conveyor_twin.micro.reference` does the same in plain Python.
"""

import math

from numba import njit
import numpy as np

from conveyor_twin.micro.collide import box_vertices, circle_circle, collide
from conveyor_twin.micro.state import (PT_BRAD, PT_E, PT_HL, PT_HW, PT_INV_INERTIA,
                                       PT_INV_MASS, PT_MU_K, PT_MU_S, PT_RADIUS, PT_SHAPE,
                                       PT_V_T, SHAPE_DISC)

# Below this approach speed [m/s] a contact is treated as plastic (no bounce).
RESTITUTION_THRESHOLD = 0.02

MODE_IMPULSE = 0
MODE_PENALTY = 1

# --- model parameter slots (float64 array ``mp``) ---
MP_SLOP = 0           # penetration left uncorrected [m]
MP_CORRECTION = 1     # fraction of the excess penetration removed per substep
MP_STIFFNESS = 2      # penalty spring [N/m]
MP_DAMPING = 3        # penalty damper [N s/m]
MP_DT = 4             # substep [s]
MP_GRAVITY = 5        # [m/s^2]
MP_FLOOR_MU = 6       # friction coefficient off the belts
MP_TRACK = 7          # 1.0: accumulate activities
MP_COLUMNS = 8

# --- activity slots [J] (Rideout and Stein: integral of |power| dt per element class) ---
A_SPRING = 0
A_DAMPER = 1
A_CONTACT_FRICTION = 2
A_BELT = 3
A_INERTIA = 4
A_COLUMNS = 5

# --- static shape table columns (float64, one row per shape) ---
SH_NV = 0
SH_OFF = 1
SH_R = 2
SH_E = 3
SH_MU = 4
SH_XMIN = 5
SH_YMIN = 6
SH_XMAX = 7
SH_YMAX = 8
SH_AX = 9             # first core vertex [m] (segments and pegs: used by the grid binning)
SH_AY = 10
SH_BX = 11            # second core vertex (pegs: the first again)
SH_BY = 12
SH_COLUMNS = 13

# --- actuator state columns (float64, one row per actuator, rewritten every substep) ---
AS_ACTIVE = 0
AS_NV = 1
AS_R = 2
AS_VX = 3             # translation velocity [m/s]
AS_VY = 4
AS_W = 5              # angular velocity about the pivot [rad/s]
AS_PX = 6             # pivot [m]
AS_PY = 7
AS_E = 8
AS_MU = 9
AS_XMIN = 10
AS_YMIN = 11
AS_XMAX = 12
AS_YMAX = 13
AS_COLUMNS = 14


@njit(cache=True, inline='always')
def friction_coefficient(mu_s, mu_k, v_t, speed):
    """Return Horváth et al.'s friction coefficient at tangential ``speed`` [m/s]."""
    if speed >= v_t:
        return mu_k
    return mu_s + (mu_k - mu_s) * (speed / v_t)


@njit(cache=True, inline='always')
def impulse_response(vax, vay, wa, ima, iia, rax, ray, vbx, vby, wb, imb, iib, rbx, rby,
                     nx, ny, e, mu_s, mu_k, v_t):
    """Return the velocities after one contact's impulses and the impulses themselves.

    :param vax: velocity of A [m/s]; ``wa`` its angular velocity [rad/s].
    :param ima: inverse mass of A [1/kg] (0: kinematic); ``iia`` inverse inertia.
    :param rax: contact point relative to A's centre (or pivot) [m]. Same for B.
    :param nx: unit normal pointing to A.
    :param e: restitution; ``mu_s``, ``mu_k``, ``v_t``: friction law.
    :return: (vax, vay, wa, vbx, vby, wb, j_n [N s], j_t [N s], u_t before friction [m/s]).
    """
    ux = (vax - wa * ray) - (vbx - wb * rby)
    uy = (vay + wa * rax) - (vby + wb * rbx)
    un = ux * nx + uy * ny
    if un >= 0.0:
        return vax, vay, wa, vbx, vby, wb, 0.0, 0.0, 0.0
    rna = rax * ny - ray * nx
    rnb = rbx * ny - rby * nx
    kn = ima + imb + iia * rna * rna + iib * rnb * rnb
    ee = e if -un > RESTITUTION_THRESHOLD else 0.0
    jn = -(1.0 + ee) * un / kn
    vax += jn * nx * ima
    vay += jn * ny * ima
    wa += iia * rna * jn
    vbx -= jn * nx * imb
    vby -= jn * ny * imb
    wb -= iib * rnb * jn
    tx = -ny
    ty = nx
    ux = (vax - wa * ray) - (vbx - wb * rby)
    uy = (vay + wa * rax) - (vby + wb * rbx)
    ut = ux * tx + uy * ty
    rta = rax * ty - ray * tx
    rtb = rbx * ty - rby * tx
    kt = ima + imb + iia * rta * rta + iib * rtb * rtb
    jt = -ut / kt
    limit = friction_coefficient(mu_s, mu_k, v_t, abs(ut)) * jn
    if jt > limit:
        jt = limit
    elif jt < -limit:
        jt = -limit
    vax += jt * tx * ima
    vay += jt * ty * ima
    wa += iia * rta * jt
    vbx -= jt * tx * imb
    vby -= jt * ty * imb
    wb -= iib * rtb * jt
    return vax, vay, wa, vbx, vby, wb, jn, jt, ut


@njit(cache=True)
def penalty_force(vax, vay, wa, ima, iia, rax, ray, vbx, vby, wb, imb, iib, rbx, rby,
                  nx, ny, depth, k, c, dt, mu_s, mu_k, v_t):
    """Return the contact force on A [N] and the powers of its spring, damper and friction [W].

    :param depth: penetration [m]; ``k`` spring [N/m], ``c`` damper [N s/m], ``dt`` substep [s].
    :return: (f_x, f_y, p_spring, p_damper, p_friction); B feels the opposite force.
    """
    ux = (vax - wa * ray) - (vbx - wb * rby)
    uy = (vay + wa * rax) - (vby + wb * rbx)
    un = ux * nx + uy * ny
    fs = k * depth
    fn = fs - c * un
    if fn <= 0.0:
        return 0.0, 0.0, abs(fs * un), 0.0, 0.0
    tx = -ny
    ty = nx
    ut = ux * tx + uy * ty
    rta = rax * ty - ray * tx
    rtb = rbx * ty - rby * tx
    kt = ima + imb + iia * rta * rta + iib * rtb * rtb
    ft = friction_coefficient(mu_s, mu_k, v_t, abs(ut)) * fn
    stick = abs(ut) / (kt * dt)
    if stick < ft:
        ft = stick
    if ut > 0.0:
        ft = -ft
    return (fn * nx + ft * tx, fn * ny + ft * ty, abs(fs * un), abs(c * un * un),
            abs(ft * ut))


@njit(cache=True)
def part_shape(pt, t, x, y, yaw, verts):
    """Fill ``verts`` with the core of a part; return (number of vertices, radius [m])."""
    if pt[t, PT_SHAPE] == SHAPE_DISC:
        verts[0, 0] = x
        verts[0, 1] = y
        return 1, pt[t, PT_RADIUS]
    box_vertices(x, y, yaw, pt[t, PT_HL], pt[t, PT_HW], verts)
    return 4, 0.0


# --- contact record columns (float64 (capacity, CT_COLUMNS)); ``cidx`` (capacity, 2) holds
# the part indices a and b (b = -1: fixed or kinematic body, its velocity in CT_BVX..CT_BW) ---
CT_NX = 0             # unit normal, pointing to a
CT_NY = 1
CT_RAX = 2            # contact point relative to a's centre [m]
CT_RAY = 3
CT_RBX = 4            # relative to b's centre or the kinematic body's pivot [m]
CT_RBY = 5
CT_DEPTH = 6          # penetration at detection [m]
CT_E = 7
CT_MU_S = 8
CT_MU_K = 9
CT_V_T = 10
CT_BVX = 11
CT_BVY = 12
CT_BW = 13
# written by :func:`prepare_contacts` before the sweeps (off the sweeps' dependency chain)
CT_IKN = 14           # 1 / normal effective mass [1/kg]
CT_IKT = 15           # 1 / tangential effective mass [1/kg]
CT_IKN_S = 16         # the same in the shock sweep (the downstream body fixed)
CT_IKT_S = 17
CT_SLOPE = 18         # (mu_k - mu_s) / v_t [s/m]
CT_WA = 19            # position correction: share of a (fraction included) [-]
CT_WB = 20
CT_CNT = 21           # change of the tangential speed per unit normal impulse [1/kg]
CT_CNT_S = 22         # the same in the shock sweep
CT_FA_S = 23          # shock sweep: 1.0 if a moves (b counts as fixed), 0.0 if b moves
CT_NEG_1PE = 24       # -(1 + e): the normal impulse factor of a bouncing contact
CT_COLUMNS = 25


@njit(cache=True, inline='always')
def _record(nc, ct, cidx, a, b, px, py, ax, ay, bx, by, nx, ny, depth, e, mu_s, mu_k, v_t,
            bvx, bvy, bw):
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


@njit(cache=True)
def _pair(i, j, ptype, x, y, yaw, pt, va, vb, out, nc, ct, cidx):
    """Record the contacts of parts i and j; return the new contact count."""
    ti = ptype[i]
    tj = ptype[j]
    if pt[ti, PT_SHAPE] == SHAPE_DISC and pt[tj, PT_SHAPE] == SHAPE_DISC:
        count = circle_circle(x[i], y[i], pt[ti, PT_RADIUS], x[j], y[j], pt[tj, PT_RADIUS], out)
    else:
        na, ra = part_shape(pt, ti, x[i], y[i], yaw[i], va)
        nb, rb = part_shape(pt, tj, x[j], y[j], yaw[j], vb)
        count = collide(va, na, ra, vb, nb, rb, out)
    if count == 0:
        return nc
    e = 0.5 * (pt[ti, PT_E] + pt[tj, PT_E])
    mu_s = 0.5 * (pt[ti, PT_MU_S] + pt[tj, PT_MU_S])
    mu_k = 0.5 * (pt[ti, PT_MU_K] + pt[tj, PT_MU_K])
    v_t = 0.5 * (pt[ti, PT_V_T] + pt[tj, PT_V_T])
    for c in range(count):
        if nc >= ct.shape[0]:
            return nc
        _record(nc, ct, cidx, i, j, out[2 + 3 * c], out[3 + 3 * c], x[i], y[i], x[j], y[j],
                out[0], out[1], out[4 + 3 * c], e, mu_s, mu_k, v_t, 0.0, 0.0, 0.0)
        nc += 1
    return nc


@njit(cache=True)
def _fixed(i, ptype, x, y, yaw, pt, va, vb, nb, rb, bvx, bvy, bw, bpx, bpy, e, mu, out,
           nc, ct, cidx):
    """Record the contacts of part i with a fixed or kinematic body (core ``vb[:nb]``)."""
    ti = ptype[i]
    na, ra = part_shape(pt, ti, x[i], y[i], yaw[i], va)
    count = collide(va, na, ra, vb, nb, rb, out)
    if count == 0:
        return nc
    # the obstacle's friction is the sliding value; the part's static/sliding ratio the static
    ratio = pt[ti, PT_MU_S] / pt[ti, PT_MU_K] if pt[ti, PT_MU_K] > 0.0 else 1.0
    for c in range(count):
        if nc >= ct.shape[0]:
            return nc
        _record(nc, ct, cidx, i, -1, out[2 + 3 * c], out[3 + 3 * c], x[i], y[i], bpx, bpy,
                out[0], out[1], out[4 + 3 * c], e, mu * ratio, mu, pt[ti, PT_V_T], bvx, bvy,
                bw)
        nc += 1
    return nc


@njit(cache=True)
def build_grid(n, x, y, gpar, gdim, cell_table, cell_items, part_cell):
    """Bin parts 0..n-1 by centre into the uniform grid: each cell's parts contiguous, ascending.

    Costs O(n), not O(cells): a cell's entries are valid only if its mark is this call's stamp,
    so no pass over the whole grid clears it (a long belt has ~10^5-10^6 cells). Two passes over
    the parts: count per cell, then place each part at its cell's cursor (a cell's range starts
    when its first part is placed), so the near phase reads every cell as one contiguous run.

    :param gpar: (x0, y0, h): grid origin and cell size [m]. :param gdim: (nx, ny).
    :param cell_table: int64[3*cells + 1], updated: ``[0, cells)`` where each cell's run starts
        in ``cell_items``, ``[cells, 2*cells)`` where it ends, ``[2*cells, 3*cells)`` the stamp
        of the call that wrote it, ``[3*cells]`` the current stamp. ``cell_items``
        int64[capacity] (output): the parts, grouped by cell; ``part_cell`` int64[capacity]
        (output): cell of each part.
    """
    x0 = gpar[0]
    y0 = gpar[1]
    inv_h = 1.0 / gpar[2]
    gnx = gdim[0]
    gny = gdim[1]
    ncell = gnx * gny
    mark = 2 * ncell
    stamp = cell_table[3 * ncell] + 1
    cell_table[3 * ncell] = stamp
    for i in range(n):
        cx = int(math.floor((x[i] - x0) * inv_h)) if x[i] == x[i] else 0
        cy = int(math.floor((y[i] - y0) * inv_h)) if y[i] == y[i] else 0
        cx = min(max(cx, 0), gnx - 1)
        cy = min(max(cy, 0), gny - 1)
        c = cy * gnx + cx
        part_cell[i] = c
        if cell_table[mark + c] != stamp:
            cell_table[mark + c] = stamp
            cell_table[c] = -1              # run not placed yet
            cell_table[ncell + c] = 0       # count
        cell_table[ncell + c] += 1
    off = 0
    for i in range(n):
        c = part_cell[i]
        if cell_table[c] < 0:
            count = cell_table[ncell + c]
            cell_table[c] = off
            cell_table[ncell + c] = off
            off += count
        k = cell_table[ncell + c]
        cell_items[k] = i
        cell_table[ncell + c] = k + 1


def grid_table(cells: int) -> np.ndarray:
    """Return the ``cell_table`` of :func:`build_grid` for a grid of ``cells`` cells."""
    return np.zeros(3 * cells + 1, dtype=np.int64)


# --- neighbour list (``nbr``, int64): header, then the ids of the parts it was built for
# (capacity), the start of each part's run of partners (capacity + 1) and the partners ---
NB_VALID = 0          # 1: holds the pairs of the parts in ``nbr[NB_HEADER:]``
NB_N = 1              # parts when built
NB_PAIRS = 2          # pairs listed
NB_BUILDS = 3         # builds so far (statistics)
NB_HEADER = 4
# A part may move this fraction of the skin before the list is rebuilt (< 1/2: two parts
# approaching each other then close less than the skin; the rest absorbs rounding).
NB_MOVE = 0.49


def neighbour_arrays(capacity: int):
    """Return the arrays of :func:`update_pairs`: ``nbr`` (int64) and ``pos0`` (2, capacity)."""
    size = NB_HEADER + 2 * capacity + 1 + CONTACTS_PER_PART * capacity
    return np.zeros(size, dtype=np.int64), np.zeros((2, capacity))


@njit(cache=True)
def update_pairs(n, ids, ptype, x, y, pt, gpar, gdim, cell_table, cell_items, part_cell, cand,
                 nbr, pos0, skin):
    """Keep the candidate pairs of parts 0..n-1 current (a Verlet list with a ``skin`` [m]).

    The list holds every pair (i, j), i < j, whose centres were closer than the sum of their
    bounding radii plus ``skin`` when it was built, in canonical order (i, then j ascending),
    and the grid cell of each part then (``part_cell``, for the static shapes; the grid's cells
    and static lists are grown by the skin). It is kept while the same parts (ids, slots) are
    present and none has moved ``NB_MOVE * skin`` since; then no pair outside it can touch, and
    the contacts are exactly those of a fresh search. Otherwise the grid is built and the
    pairs searched again. In a jam the list lives for many steps; in free flow at a speed v it
    is rebuilt every ``NB_MOVE * skin / (v dt)`` steps.

    :param nbr: int64 list (see :func:`neighbour_arrays`), updated. :param pos0: (2, capacity)
        positions at the build [m], updated. :param skin: [m]; the grid cell must be at least
        twice the largest bounding radius plus ``skin``.
    :return: 0 kept, 1 rebuilt, 2 rebuilt but full (pairs beyond the capacity are dropped and
        the next call rebuilds).
    """
    cap = pos0.shape[1]
    o_ids = NB_HEADER
    o_start = o_ids + cap
    o_j = o_start + cap + 1
    jcap = nbr.shape[0] - o_j
    if nbr[NB_VALID] == 1 and nbr[NB_N] == n:
        lim = (NB_MOVE * skin) ** 2
        keep = True
        for i in range(n):
            dx = x[i] - pos0[0, i]
            dy = y[i] - pos0[1, i]
            if nbr[o_ids + i] != ids[i] or not dx * dx + dy * dy < lim:
                keep = False
                break
        if keep:
            return 0
    build_grid(n, x, y, gpar, gdim, cell_table, cell_items, part_cell)
    nbr[NB_BUILDS] += 1
    gnx = gdim[0]
    gny = gdim[1]
    ncell = gnx * gny
    mark = 2 * ncell
    stamp = cell_table[3 * ncell]
    npairs = 0
    full = False
    for i in range(n):
        nbr[o_ids + i] = ids[i]
        pos0[0, i] = x[i]
        pos0[1, i] = y[i]
        nbr[o_start + i] = npairs
        bri = pt[ptype[i], PT_BRAD] + skin
        c = part_cell[i]
        cy = c // gnx
        cx = c - cy * gnx
        m = 0
        xi = x[i]
        yi = y[i]
        gx0 = max(cx - 1, 0)
        gx1 = min(cx + 1, gnx - 1)
        for gy in range(max(cy - 1, 0), min(cy + 2, gny)):
            row = gy * gnx
            for c9 in range(row + gx0, row + gx1 + 1):
                if cell_table[mark + c9] != stamp:
                    continue  # empty since the last build
                for k in range(cell_table[c9], cell_table[ncell + c9]):
                    j = cell_items[k]
                    dx = x[j] - xi
                    dy = y[j] - yi
                    rr = bri + pt[ptype[j], PT_BRAD]
                    if j > i and dx * dx + dy * dy < rr * rr:
                        # insertion sort by j: canonical order whatever order cells are read
                        p = m
                        while p > 0 and cand[p - 1] > j:
                            cand[p] = cand[p - 1]
                            p -= 1
                        cand[p] = j
                        m += 1
        if npairs + m > jcap:
            m = jcap - npairs
            full = True
        for p in range(m):
            nbr[o_j + npairs + p] = cand[p]
        npairs += m
    nbr[o_start + n] = npairs
    nbr[NB_N] = n
    nbr[NB_PAIRS] = npairs
    nbr[NB_VALID] = 0 if full else 1
    return 2 if full else 1


@njit(cache=True)
def detect(n, ptype, x, y, yaw, pt, nbr, part_cell, static_start, static_items, shp, shp_verts,
           act_state, act_verts, va, vb, out, ct, cidx):
    """Record every contact of parts 0..n-1 in the canonical order; return how many.

    :param nbr, part_cell: the neighbour list and the parts' grid cells as
        :func:`update_pairs` left them (current for these positions).
    :param shp: static shape table (S, SH_COLUMNS); ``shp_verts`` (V, 2) their cores [m].
    :param act_state: actuator table (A, AS_COLUMNS); ``act_verts`` (A, 4, 2) their cores.
    :param static_start: int64[cells + 1], ``static_items``: the static shapes of each cell.
    :param va: (4, 2) scratch; ``vb`` (4, 2) scratch; ``out`` float64[8].
    :param ct: (C, CT_COLUMNS) contact records, ``cidx`` (C, 2) their bodies (output). When
        full, further contacts are dropped (the caller sizes it; see ``contacts_full``).
    """
    cap = part_cell.shape[0]
    o_start = NB_HEADER + cap
    o_j = o_start + cap + 1
    nc = 0
    for i in range(n):
        bri = pt[ptype[i], PT_BRAD]
        xi = x[i]
        yi = y[i]
        ti = ptype[i]
        disc_i = pt[ti, PT_SHAPE] == SHAPE_DISC
        for p in range(nbr[o_start + i], nbr[o_start + i + 1]):
            j = nbr[o_j + p]
            tj = ptype[j]
            dx = x[j] - xi
            dy = y[j] - yi
            rr = bri + pt[tj, PT_BRAD]
            if dx * dx + dy * dy >= rr * rr:
                continue  # listed within the skin, not within the bounding radii
            if disc_i and pt[tj, PT_SHAPE] == SHAPE_DISC:
                # disc-disc, the common case, written out (same arithmetic as circle_circle)
                dx = xi - x[j]
                dy = yi - y[j]
                rsum = pt[ti, PT_RADIUS] + pt[tj, PT_RADIUS]
                d2 = dx * dx + dy * dy
                if d2 >= rsum * rsum or nc >= ct.shape[0]:
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
                _record(nc, ct, cidx, i, j, x[j] + nx * rb, y[j] + ny * rb, xi, yi, x[j], y[j],
                        nx, ny, depth, 0.5 * (pt[ti, PT_E] + pt[tj, PT_E]),
                        0.5 * (pt[ti, PT_MU_S] + pt[tj, PT_MU_S]),
                        0.5 * (pt[ti, PT_MU_K] + pt[tj, PT_MU_K]),
                        0.5 * (pt[ti, PT_V_T] + pt[tj, PT_V_T]), 0.0, 0.0, 0.0)
                nc += 1
            else:
                nc = _pair(i, j, ptype, x, y, yaw, pt, va, vb, out, nc, ct, cidx)
    for i in range(n):
        bri = pt[ptype[i], PT_BRAD]
        c = part_cell[i]
        for k in range(static_start[c], static_start[c + 1]):
            s = static_items[k]
            if (x[i] + bri <= shp[s, SH_XMIN] or x[i] - bri >= shp[s, SH_XMAX]
                    or y[i] + bri <= shp[s, SH_YMIN] or y[i] - bri >= shp[s, SH_YMAX]):
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
                if d2 >= rsum * rsum or nc >= ct.shape[0]:
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
                _record(nc, ct, cidx, i, -1, qx + nx * (rb - 0.5 * depth),
                        qy + ny * (rb - 0.5 * depth), x[i], y[i], 0.0, 0.0, nx, ny, depth,
                        shp[s, SH_E], mu * ratio, mu, pt[ti, PT_V_T], 0.0, 0.0, 0.0)
                nc += 1
                continue
            nc = _fixed(i, ptype, x, y, yaw, pt, va, shp_verts[off:off + nv], nv,
                        shp[s, SH_R], 0.0, 0.0, 0.0, 0.0, 0.0, shp[s, SH_E], shp[s, SH_MU],
                        out, nc, ct, cidx)
        for a in range(act_state.shape[0]):
            if act_state[a, AS_ACTIVE] == 0.0:
                continue
            if (x[i] + bri <= act_state[a, AS_XMIN] or x[i] - bri >= act_state[a, AS_XMAX]
                    or y[i] + bri <= act_state[a, AS_YMIN]
                    or y[i] - bri >= act_state[a, AS_YMAX]):
                continue
            nc = _fixed(i, ptype, x, y, yaw, pt, va, act_verts[a], int(act_state[a, AS_NV]),
                        act_state[a, AS_R], act_state[a, AS_VX], act_state[a, AS_VY],
                        act_state[a, AS_W], act_state[a, AS_PX], act_state[a, AS_PY],
                        act_state[a, AS_E], act_state[a, AS_MU], out, nc, ct, cidx)
    return nc


@njit(cache=True, inline='always')
def _masses(ima, iia, imb, iib, rax, ray, rbx, rby, nx, ny):
    """Return a contact's inverse normal and tangential effective masses ``kn``, ``kt`` [1/kg]
    and the change of its tangential speed per unit normal impulse [1/kg]."""
    rna = rax * ny - ray * nx
    rnb = rbx * ny - rby * nx
    rta = rax * nx + ray * ny
    rtb = rbx * nx + rby * ny
    kn = ima + imb + iia * rna * rna + iib * rnb * rnb
    kt = ima + imb + iia * rta * rta + iib * rtb * rtb
    return kn, kt, iia * rna * rta + iib * rnb * rtb


@njit(cache=True)
def prepare_contacts(nc, ct, cidx, ptype, pt, passes, key, mp):
    """Write the per-contact constants of the impulse and position sweeps (one pass).

    Geometry only, so the divisions happen here, where they overlap, and the sweeps only
    multiply: the inverse normal and tangential effective masses and the change of the
    tangential speed per unit normal impulse (also with the downstream body fixed, for the
    shock sweep), the friction slope, ``-(1 + e)``, which body moves in the shock sweeps
    (``passes >= 2``; ``key``: position along the belt [m]) and the shares of the position
    correction (inverse-mass proportion times ``mp[MP_CORRECTION]``).
    """
    frac = mp[MP_CORRECTION]
    shocking = passes >= 2
    last_vt = last_mu_k = last_mu_s = math.nan     # NaN: differs from everything
    last_ima = last_imb = math.nan
    last_kn = last_kn_s = math.nan
    last_ikn = last_ikn_s = 0.0
    slope = 0.0
    w = 0.0
    for c in range(nc):
        a = cidx[c, 0]
        b = cidx[c, 1]
        ta = ptype[a]
        ima = pt[ta, PT_INV_MASS]
        iia = pt[ta, PT_INV_INERTIA]
        imb = 0.0
        iib = 0.0
        if b >= 0:
            tb = ptype[b]
            imb = pt[tb, PT_INV_MASS]
            iib = pt[tb, PT_INV_INERTIA]
        rax = ct[c, CT_RAX]
        ray = ct[c, CT_RAY]
        rbx = ct[c, CT_RBX]
        rby = ct[c, CT_RBY]
        nx = ct[c, CT_NX]
        ny = ct[c, CT_NY]
        kn, kt, cnt = _masses(ima, iia, imb, iib, rax, ray, rbx, rby, nx, ny)
        # a disc's contact normal runs through its centre: the normal effective mass is the
        # same for every contact of the same bodies' types, so its reciprocal is reused
        if kn != last_kn:
            last_kn = kn
            last_ikn = 1.0 / kn
        ct[c, CT_IKN] = last_ikn
        ct[c, CT_IKT] = 1.0 / kt
        ct[c, CT_CNT] = cnt
        ct[c, CT_FA_S] = 1.0
        if shocking and b >= 0:
            if key[a] > key[b]:
                ct[c, CT_FA_S] = 0.0
                kn, kt, cnt = _masses(0.0, 0.0, imb, iib, rax, ray, rbx, rby, nx, ny)
            else:
                kn, kt, cnt = _masses(ima, iia, 0.0, 0.0, rax, ray, rbx, rby, nx, ny)
            if kn != last_kn_s:
                last_kn_s = kn
                last_ikn_s = 1.0 / kn
            ct[c, CT_IKN_S] = last_ikn_s
            ct[c, CT_IKT_S] = 1.0 / kt
            ct[c, CT_CNT_S] = cnt
        else:
            ct[c, CT_IKN_S] = ct[c, CT_IKN]
            ct[c, CT_IKT_S] = ct[c, CT_IKT]
            ct[c, CT_CNT_S] = ct[c, CT_CNT]
        # the same materials and masses as the contact before (the common case): the same
        # quotients, without dividing again
        v_t = ct[c, CT_V_T]
        mu_k = ct[c, CT_MU_K]
        mu_s = ct[c, CT_MU_S]
        if v_t != last_vt or mu_k != last_mu_k or mu_s != last_mu_s:
            last_vt = v_t
            last_mu_k = mu_k
            last_mu_s = mu_s
            slope = (mu_k - mu_s) / v_t if v_t > 0.0 else 0.0
        ct[c, CT_SLOPE] = slope
        ct[c, CT_NEG_1PE] = -(1.0 + ct[c, CT_E])
        if ima != last_ima or imb != last_imb:
            last_ima = ima
            last_imb = imb
            w = frac / (ima + imb)
        ct[c, CT_WA] = w * ima
        ct[c, CT_WB] = w * imb


@njit(cache=True)
def solve_impulses(nc, ct, cidx, ptype, vx, vy, wz, pt, passes, key, mp, acc):
    """Apply the contacts' impulses in ``passes`` sweeps (canonical order).

    The first sweep is Hoher et al.'s response, with restitution. Further sweeps are plastic and
    touch only contacts still closing (so they change nothing for isolated impacts). With
    ``passes >= 2`` the last sweep is a shock-propagation sweep: of two parts the one further
    downstream (larger ``key``, its position along its belt's direction [m]) counts as fixed,
    so a pile pressed by the belt against an obstacle is stopped in one sweep.

    The sweeps are Gauss-Seidel: each contact sees the velocities left by the ones before it,
    so the per-contact work is a dependency chain; the records must have been prepared by
    :func:`prepare_contacts` (the sweeps only multiply). Each impulse is that of
    :func:`impulse_response`.
    """
    track = mp[MP_TRACK] != 0.0
    shocking = passes >= 2
    for it in range(passes):
        shock = shocking and it == passes - 1
        ikn_col = CT_IKN_S if shock else CT_IKN
        ikt_col = CT_IKT_S if shock else CT_IKT
        cnt_col = CT_CNT_S if shock else CT_CNT
        first = it == 0
        # branch-free per contact (the outcome of closing/separating, sticking/sliding is
        # data-dependent and would mispredict): a separating contact gets jn = 0, hence jt = 0
        for c in range(nc):
            a = cidx[c, 0]
            b = cidx[c, 1]
            fa = 1.0
            fb = 1.0
            if shock:
                fa = ct[c, CT_FA_S]
                fb = 1.0 - fa
            ta = ptype[a]
            ima = pt[ta, PT_INV_MASS] * fa
            iia = pt[ta, PT_INV_INERTIA] * fa
            if b >= 0:
                tb = ptype[b]
                imb = pt[tb, PT_INV_MASS] * fb
                iib = pt[tb, PT_INV_INERTIA] * fb
                vbx = vx[b]
                vby = vy[b]
                wb = wz[b]
            else:
                imb = 0.0
                iib = 0.0
                vbx = ct[c, CT_BVX]
                vby = ct[c, CT_BVY]
                wb = ct[c, CT_BW]
            vax = vx[a]
            vay = vy[a]
            wa = wz[a]
            rax = ct[c, CT_RAX]
            ray = ct[c, CT_RAY]
            rbx = ct[c, CT_RBX]
            rby = ct[c, CT_RBY]
            nx = ct[c, CT_NX]
            ny = ct[c, CT_NY]
            # normal and tangential relative speeds from the same velocities; the tangential
            # speed after the normal impulse follows algebraically (CT_CNT), which keeps the
            # chain from one contact to the next short
            ux = (vax - wa * ray) - (vbx - wb * rby)
            uy = (vay + wa * rax) - (vby + wb * rbx)
            un = ux * nx + uy * ny
            # -(1 + e) when bouncing, else -1 (the same numbers as -(1 + 0))
            f = ct[c, CT_NEG_1PE] if first and -un > RESTITUTION_THRESHOLD else -1.0
            jn = max(f * un * ct[c, ikn_col], 0.0)
            ut = (uy * nx - ux * ny) + jn * ct[c, cnt_col]
            jt = -ut * ct[c, ikt_col]
            speed = abs(ut)
            mu = (ct[c, CT_MU_S] + ct[c, CT_SLOPE] * speed if speed < ct[c, CT_V_T]
                  else ct[c, CT_MU_K])
            limit = mu * jn
            jt = min(max(jt, -limit), limit)
            # total impulse along x, y (t = (-ny, nx)) and its moments
            px = jn * nx - jt * ny
            py = jn * ny + jt * nx
            vx[a] = vax + px * ima
            vy[a] = vay + py * ima
            wz[a] = wa + iia * (rax * py - ray * px)
            if b >= 0:
                vx[b] = vbx - px * imb
                vy[b] = vby - py * imb
                wz[b] = wb - iib * (rbx * py - rby * px)
            if track:
                acc[A_CONTACT_FRICTION] += abs(jt * ut)


@njit(cache=True)
def correct_positions(nc, ct, cidx, ptype, x, y, x0, y0, pt, passes, key, mp):
    """Push overlapping bodies apart along the contact normals (translation only).

    The depth of each contact is estimated from its detected depth and how far its bodies
    moved since (``x0``, ``y0``: positions at detection); each sweep removes
    ``mp[MP_CORRECTION]`` of the excess over the slop, in inverse-mass proportion; the last of
    ``passes >= 2`` sweeps moves only the upstream part of a pair (see :func:`solve_impulses`).
    The shares come from :func:`prepare_contacts` (no division in the chain).
    """
    slop = mp[MP_SLOP]
    frac = mp[MP_CORRECTION]
    shocking = passes >= 2
    for it in range(passes):
        shock = shocking and it == passes - 1
        # branch-free per contact, as in solve_impulses (no excess: a zero move)
        for c in range(nc):
            a = cidx[c, 0]
            b = cidx[c, 1]
            nx = ct[c, CT_NX]
            ny = ct[c, CT_NY]
            moved = nx * (x[a] - x0[a]) + ny * (y[a] - y0[a])
            if shock:
                wa = frac * ct[c, CT_FA_S]
                wb = frac - wa
            else:
                wa = ct[c, CT_WA]
                wb = ct[c, CT_WB]
            if b >= 0:
                moved -= nx * (x[b] - x0[b]) + ny * (y[b] - y0[b])
            excess = max(ct[c, CT_DEPTH] - moved - slop, 0.0)
            x[a] += nx * excess * wa
            y[a] += ny * excess * wa
            if b >= 0:
                x[b] -= nx * excess * wb
                y[b] -= ny * excess * wb


@njit(cache=True)
def penalty_forces(nc, ct, cidx, ptype, vx, vy, wz, fx, fy, tz, pt, mp, acc):
    """Accumulate the penalty spring-damper and friction forces of the contacts [N, N m]."""
    track = mp[MP_TRACK] != 0.0
    dt = mp[MP_DT]
    for c in range(nc):
        a = cidx[c, 0]
        b = cidx[c, 1]
        ta = ptype[a]
        if b >= 0:
            tb = ptype[b]
            bvx = vx[b]
            bvy = vy[b]
            bw = wz[b]
            imb = pt[tb, PT_INV_MASS]
            iib = pt[tb, PT_INV_INERTIA]
        else:
            bvx = ct[c, CT_BVX]
            bvy = ct[c, CT_BVY]
            bw = ct[c, CT_BW]
            imb = 0.0
            iib = 0.0
        rax = ct[c, CT_RAX]
        ray = ct[c, CT_RAY]
        rbx = ct[c, CT_RBX]
        rby = ct[c, CT_RBY]
        fcx, fcy, ps, pd, pf = penalty_force(
            vx[a], vy[a], wz[a], pt[ta, PT_INV_MASS], pt[ta, PT_INV_INERTIA], rax, ray,
            bvx, bvy, bw, imb, iib, rbx, rby, ct[c, CT_NX], ct[c, CT_NY], ct[c, CT_DEPTH],
            mp[MP_STIFFNESS], mp[MP_DAMPING], dt, ct[c, CT_MU_S], ct[c, CT_MU_K],
            ct[c, CT_V_T])
        fx[a] += fcx
        fy[a] += fcy
        tz[a] += rax * fcy - ray * fcx
        if b >= 0:
            fx[b] -= fcx
            fy[b] -= fcy
            tz[b] -= rbx * fcy - rby * fcx
        if track:
            acc[A_SPRING] += ps * dt
            acc[A_DAMPER] += pd * dt
            acc[A_CONTACT_FRICTION] += pf * dt


# contact records per part slot
CONTACTS_PER_PART = 8


def scratch(capacity: int):
    """Return the scratch arrays of the contact kernels: (cand, va, vb, out, ct, cidx)."""
    size = CONTACTS_PER_PART * capacity
    return (np.zeros(capacity + 1, dtype=np.int64), np.zeros((4, 2)), np.zeros((4, 2)),
            np.zeros(8), np.zeros((size, CT_COLUMNS)), np.zeros((size, 2), dtype=np.int64))
