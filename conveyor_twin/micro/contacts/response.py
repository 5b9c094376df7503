"""Contact response: impulses (Hoher et al.) or penalty spring-dampers (Rideout, Stein).

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

Why two sweeps in the impulse model (``CONTACT_PASSES = 2`` in :mod:`conveyor_twin.micro.sim`),
although Hoher et al. solve each contact once: every contact is still one algebraic equation,
solved a fixed number of times per substep (no iteration to a tolerance, so cost and result stay
time-deterministic), but a single sweep does not hold a jam. The second sweep is a plastic
shock-propagation sweep (the downstream body of a pair counts as fixed) over the same contacts, and
the position correction does the same. Measured on the benchmark jam (``conveyor-twin bench micro``
scene, 4 s, checked every 0.1 s): with one sweep the deepest disc overlap reaches 9.7 mm (N = 300),
10.0 mm (N = 1000) and 9.99 mm (N = 5000) for 10 mm discs, i.e. parts pass through each other under
the belt's push (each substep's correction of 80 % of a contact's excess is undone by the next rows
pushing); with two sweeps it stays at 0.24, 0.24 and 0.93 mm. So the second sweep stays;
"penetration resolved every step" needs it once contacts share bodies.

The interface: the narrow phase's records ``ct`` (C, CT_COLUMNS) and bodies ``cidx`` (C, 2)
(``nc`` of them, canonical order) in; the parts' velocities (impulse model:
:func:`prepare_contacts`, :func:`solve_impulses`; penalty model: :func:`penalty_forces` into
force arrays) and positions (:func:`correct_positions`) updated in place, the activities
``acc`` accumulated. Nothing here looks at geometry beyond the records.
"""

import math

from numba import njit

from conveyor_twin.micro.contacts.tables import (A_CONTACT_FRICTION, A_DAMPER, A_SPRING, CT_BVX,
                                                 CT_BVY, CT_BW, CT_CNT, CT_CNT_S, CT_DEPTH,
                                                 CT_E, CT_FA_S, CT_IKN, CT_IKN_S, CT_IKT,
                                                 CT_IKT_S, CT_MU_K, CT_MU_S, CT_NEG_1PE, CT_NX,
                                                 CT_NY, CT_RAX, CT_RAY, CT_RBX, CT_RBY,
                                                 CT_SLOPE, CT_V_T, CT_WA, CT_WB, MP_CORRECTION,
                                                 MP_DAMPING, MP_DT, MP_SLOP, MP_STIFFNESS,
                                                 MP_TRACK)
from conveyor_twin.micro.state import PT_INV_INERTIA, PT_INV_MASS

# Below this approach speed [m/s] a contact is treated as plastic (no bounce).
RESTITUTION_THRESHOLD = 0.02

MODE_IMPULSE = 0
MODE_PENALTY = 1


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
