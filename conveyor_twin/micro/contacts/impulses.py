"""The impulse model: sequential impulses at the contacts and the position correction.

Equal and opposite impulses at each contact point, applied to both bodies at the point's arms
(``r_a``, ``r_b`` from one point), mass- and inertia-weighted through the effective masses
``k_n = 1/m_a + 1/m_b + (r_a x n)^2 / I_a + (r_b x n)^2 / I_b`` (fixed and kinematic bodies:
infinite mass). They are solved as sequential impulses (Catto; Erleben's projected
Gauss-Seidel) in the arrangement of Box2D v3's solver, per substep:

1. :func:`prepare_contacts`: constants, the bounce from the approach before any impulse, and the
   warm start (each contact starts from its impulses one substep earlier: in a jam they are
   what holds back the belt's push);
2. :func:`solve_impulses`: sweeps, alternating forward and backward, each contact's accumulated
   normal impulse kept >= 0 and bringing the relative normal speed to 0, or to ``-gap / h`` for
   a speculative contact (recorded by the near phase before the bodies touch: the gap closes
   exactly within the substep), the accumulated tangential impulse clamped to the Coulomb cone
   ``mu(|u_t|)`` times the normal one (Horváth et al.'s speed-dependent coefficient); until no
   increment changes a relative speed by more than the cell's tolerance, at most as many
   sweeps' contact visits as its budget buys (:func:`sweep_limit`); between two sweeps over
   every contact, up to :data:`PARTIAL_SWEEPS` sweeps over the contacts of the parts still
   moving (the rest of a jam waits for the few contacts that converge slowly);
3. :func:`~.restitution.restitute`: restitution in a pass of its own: Poisson's, on their
   compression swept to convergence, for the new impacts of islands neither held from the
   substep before nor driven by an actuator (so impacts that happen at once keep their
   energy), elsewhere the bounce from the approach speeds stored before the solve;
4. :func:`~.energy.limit_energy`: no island gains more kinetic energy than the external work.

What holds, to round-off, in every sweep: total linear and angular momentum (each impulse has
its partner, at the same point). Kinetic energy is bounded by the energy limit (a warm start's
stale impulse, or an increment taking back impulse, could add some). Penetration beyond the
slop is removed by moving positions only (:func:`correct_positions`,
:data:`~conveyor_twin.micro.sim.POSITION_PASSES` sweeps, inverse-mass proportion along ``n``):
it never feeds into velocities, so it adds no energy and no momentum (the centre of mass stays;
the angular momentum about a fixed point changes by ``m dx x v`` where bodies slide past each
other while they overlap).

Why warm starting: momentum-conserving sweeps without memory carry an impulse only a contact or
two further per sweep, so the belt's push on a jam of many rows is never taken back; with the
warm start a jam at rest needs few sweeps to meet the tolerance (the bench jam of
``conveyor-twin bench micro`` keeps its deepest overlap at the slop, 0.1 mm of 10 mm discs).
The sweeps' number depends only on the contacts' values: the same inputs give the same result,
bit for bit.
"""

import math

from numba import njit

from conveyor_twin.micro.contacts.response import friction_coefficient
from conveyor_twin.micro.contacts.restitution import (RESTITUTION_THRESHOLD, sweep_contact,
                                                      sweep_plan)
from conveyor_twin.micro.contacts.tables import (A_CONTACT_FRICTION, CT_BOUNCE, CT_BVX, CT_BVY,
                                                 CT_BW, CT_CNT, CT_DEPTH, CT_E, CT_IKN, CT_IKT,
                                                 CT_KA, CT_KB, CT_LN, CT_LN0, CT_LT, CT_MU_K,
                                                 CT_MU_S, CT_NX, CT_NY, CT_RAX, CT_RAY, CT_RBX,
                                                 CT_RBY, CT_KN, CT_SLOPE, CT_TARGET, CT_V_T, CT_WA,
                                                 CT_WB, MP_CORRECTION, MP_DT, MP_SLOP,
                                                 MP_MAX_SWEEPS, MP_SWEEP_WORK, MP_TOLERANCE,
                                                 MP_TRACK, PV_KA, PV_KB, PV_LN, PV_LT)
from conveyor_twin.micro.state import PT_INV_INERTIA, PT_INV_MASS

PARTIAL_SWEEPS = 8      # the most partial sweeps between two full ones
MOVING_SHARE = 0.5      # a part moves in a sweep while one of its increments exceeds this share
                        # of the tolerance


@njit(cache=True, inline='always')
def impulse_response(a, b, nx, ny, e, friction):
    """Return the velocities after one contact's impulses and the impulses themselves.

    :param a: body A, ``(vx, vy, w, im, ii, rx, ry)``: velocity [m/s], angular velocity
        [rad/s], inverse mass [1/kg] (0: kinematic), inverse inertia, contact point relative
        to its centre (or pivot) [m]. ``b``: body B, the same.
    :param nx: unit normal pointing to A, with ``ny``.
    :param e: restitution; ``friction``: ``(mu_s, mu_k, v_t)``, the friction law.
    :return: (vax, vay, wa, vbx, vby, wb, j_n [N s], j_t [N s], u_t before friction [m/s]).
    """
    vax, vay, wa, ima, iia, rax, ray = a
    vbx, vby, wb, imb, iib, rbx, rby = b
    mu_s, mu_k, v_t = friction
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
def prepare_contacts(nc, ct, cidx, ptype, pt, mp, vx, vy, wz, v0x, v0y, w0, prev):
    """Write the per-contact constants of the impulse and position sweeps and apply the warm
    start (one pass); return how many contacts found their predecessor and how many bounce.

    Constants: geometry only, so the divisions happen here, where they overlap, and the sweeps
    only multiply: the inverse normal and tangential effective masses, the change of the
    tangential speed per unit normal impulse, the friction slope, the shares of the
    position correction (inverse-mass proportion times ``mp[MP_CORRECTION]``) and the least
    normal speed the sweeps allow (``CT_TARGET``: 0 for touching bodies, ``-gap / h`` for a
    speculative contact, ``h = mp[MP_DT]``). The bounce (``CT_BOUNCE``): ``e`` times the normal
    approach speed before any impulse of the substep (``v0x``, ``v0y``, ``w0``: the velocities
    then), 0 below :data:`RESTITUTION_THRESHOLD`; :func:`~.restitution.restitute` applies it
    after the sweeps.

    Warm start (Catto): a contact takes the accumulated impulses of the previous substep's
    contact with the same keys (``CT_KA``, ``CT_KB``; both lists ascend in the canonical order,
    so one merge finds them), the tangential one clamped to ``mu_s`` times the normal one, and
    applies them to both bodies (``vx``, ``vy``, ``wz``), equal and opposite, at the contact
    point; the normal one is kept in ``CT_LN0`` (0 without a predecessor) for the restitution.
    In a jam the previous impulses are what holds back the belt's push, so the sweeps start
    from them instead of building a force chain through hundreds of parts anew every substep.

    :param prev: (C + 1, PV_COLUMNS) the previous contacts' keys and impulses, row C their count.
    """
    frac = mp[MP_CORRECTION]
    last_vt = last_mu_k = last_mu_s = math.nan     # NaN: differs from everything
    last_ima = last_imb = math.nan
    last_kn = math.nan
    last_ikn = 0.0
    slope = 0.0
    w = 0.0
    nprev = int(prev[prev.shape[0] - 1, 0])
    inv_h = 1.0 / mp[MP_DT]
    q = 0
    found = 0
    bounces = 0
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
            vbx = v0x[b]
            vby = v0y[b]
            wb = w0[b]
        else:
            vbx = ct[c, CT_BVX]
            vby = ct[c, CT_BVY]
            wb = ct[c, CT_BW]
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
        ct[c, CT_KN] = kn
        ct[c, CT_IKT] = 1.0 / kt
        # a speculative contact (depth < 0: a gap) lets the bodies close it within the substep
        ct[c, CT_TARGET] = min(ct[c, CT_DEPTH], 0.0) * inv_h
        ct[c, CT_CNT] = cnt
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
        if ima != last_ima or imb != last_imb:
            last_ima = ima
            last_imb = imb
            w = frac / (ima + imb)
        ct[c, CT_WA] = w * ima
        ct[c, CT_WB] = w * imb
        un = (((v0x[a] - w0[a] * ray) - (vbx - wb * rby)) * nx
              + ((v0y[a] + w0[a] * rax) - (vby + wb * rbx)) * ny)
        bounce = ct[c, CT_E] * -un if -un > RESTITUTION_THRESHOLD else 0.0
        ct[c, CT_BOUNCE] = bounce
        bounces += bounce > 0.0
        # warm start
        ct[c, CT_LN0] = 0.0
        ka = ct[c, CT_KA]
        kb = ct[c, CT_KB]
        while q < nprev and (prev[q, PV_KA] < ka or (prev[q, PV_KA] == ka
                                                     and prev[q, PV_KB] < kb)):
            q += 1
        if q < nprev and prev[q, PV_KA] == ka and prev[q, PV_KB] == kb:
            found += 1
            ln = prev[q, PV_LN]
            limit = mu_s * ln
            lt = min(max(prev[q, PV_LT], -limit), limit)
            ct[c, CT_LN] = ln
            ct[c, CT_LN0] = ln
            ct[c, CT_LT] = lt
            px = ln * nx - lt * ny
            py = ln * ny + lt * nx
            vx[a] += px * ima
            vy[a] += py * ima
            wz[a] += iia * (rax * py - ray * px)
            if b >= 0:
                vx[b] -= px * imb
                vy[b] -= py * imb
                wz[b] -= iib * (rbx * py - rby * px)
    return found, bounces


@njit(cache=True, inline='always')
def sweep_limit(nc, passes, mp):
    """Return the most impulse sweeps of a substep with ``nc`` contacts.

    As many sweeps over the ``nc`` contacts as ``mp[MP_SWEEP_WORK]`` contact visits pay for, at
    least ``passes`` and at most ``mp[MP_MAX_SWEEPS]``; ``passes`` alone without a budget
    (``MP_SWEEP_WORK`` 0). The limit depends on the number of contacts only, so the same inputs
    give the same sweeps.
    """
    work = mp[MP_SWEEP_WORK]
    if work <= 0.0 or nc == 0:
        return passes
    return max(passes, min(int(mp[MP_MAX_SWEEPS]), int(work) // nc))


@njit(cache=True)
def solve_impulses(nc, ct, cidx, ptype, vx, vy, wz, pt, passes, mp, acc, prev, marks):
    """Apply the contacts' impulses in sweeps after the warm start of :func:`prepare_contacts`
    until no contact's increment changes a relative speed by more than ``mp[MP_TOLERANCE]``
    [m/s], at most as many contact visits as the full sweeps :func:`sweep_limit` allows
    (``passes`` at least) make; keep the keys and accumulated impulses in ``prev`` for the next
    substep. Return the number of full sweeps.

    Full and partial sweeps: after a full sweep (every contact) that has not converged, up to
    :data:`PARTIAL_SWEEPS` partial sweeps visit only the contacts of the parts that moved in
    the sweep before (an increment above :data:`MOVING_SHARE` of the tolerance on one of their
    contacts), until none moved; then a full sweep again. Only a full sweep ends the solve as
    converged; every visit, in partial sweeps too, counts against the budget, so a jam that
    does not converge costs what its full sweeps alone would. In a jam a few contacts around
    one part converge slowly while hundreds have converged; the partial sweeps spend the work
    on those few. ``marks`` (scratch, two rows or more of one column per part, overwritten):
    per part, the last even and the last odd sweep it moved in.

    Sequential impulses with accumulated impulses (Catto; Erleben's projected Gauss-Seidel):
    every impulse acts on both bodies of its contact, equal and opposite, at the contact point
    (the same point for both, so the moments are those of one force), so every sweep keeps
    total linear and angular momentum to round-off. Each contact's normal impulse accumulated
    over the substep stays >= 0 and brings the relative normal speed ``u_n`` to its target
    (``CT_TARGET``: 0, or ``-gap / h`` for a speculative contact, which then closes its gap
    exactly); restitution comes afterwards (:func:`~.restitution.restitute`). The accumulated
    tangential impulse is clamped to the Coulomb cone ``[-mu ln, mu ln]`` (``mu`` Horváth et
    al.'s speed-dependent coefficient at the current sliding speed), so no contact ever holds
    more than its normal impulse allows. Sweeps alternate forward and backward over the
    contacts (:func:`~.restitution.sweep_contact`), so no contact is always solved last.

    The stopping rule depends on the contacts' values only: the same inputs give the same
    number of sweeps, bit for bit. The records must have been prepared by
    :func:`prepare_contacts` (the sweeps only multiply); the per-contact work is branch-free
    (the outcome of closing/separating, sticking/sliding is data-dependent and would
    mispredict).
    """
    track = mp[MP_TRACK] != 0.0
    tol = mp[MP_TOLERANCE]
    pairs, half, visits = sweep_plan(nc, cidx)
    sweeps = sweep_limit(nc, passes, mp)
    for c in range(nc):
        for side in range(2):
            i = cidx[c, side]
            if i >= 0:
                marks[0, i] = -1.0
                marks[1, i] = -1.0
    moving = MOVING_SHARE * tol
    budget = sweeps * nc   # contact visits
    used = 0
    done = 0          # full sweeps
    it = -1           # sweeps, full and partial
    full = True
    partial = 0       # partial sweeps since the last full one
    while True:
        it += 1
        residual = 0.0
        moved = False
        before = float(it - 1)
        mark = float(it)
        last = marks[(it + 1) % 2]
        now = marks[it % 2]
        for kk in range(visits):
            k = kk if it % 2 == 0 else visits - 1 - kk
            c = sweep_contact(k, pairs, half)
            if c < 0:
                continue
            a = cidx[c, 0]
            b = cidx[c, 1]
            if not full and last[a] != before and (b < 0 or last[b] != before):
                continue
            used += 1
            ta = ptype[a]
            ima = pt[ta, PT_INV_MASS]
            iia = pt[ta, PT_INV_INERTIA]
            if b >= 0:
                tb = ptype[b]
                imb = pt[tb, PT_INV_MASS]
                iib = pt[tb, PT_INV_INERTIA]
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
            ln = ct[c, CT_LN]
            ln1 = max(ln + (ct[c, CT_TARGET] - un) * ct[c, CT_IKN], 0.0)
            jn = ln1 - ln
            ut = (uy * nx - ux * ny) + jn * ct[c, CT_CNT]
            speed = abs(ut)
            mu = (ct[c, CT_MU_S] + ct[c, CT_SLOPE] * speed if speed < ct[c, CT_V_T]
                  else ct[c, CT_MU_K])
            limit = mu * ln1
            lt = ct[c, CT_LT]
            lt1 = min(max(lt - ut * ct[c, CT_IKT], -limit), limit)
            jt = lt1 - lt
            ct[c, CT_LN] = ln1
            ct[c, CT_LT] = lt1
            change = (abs(jn) + abs(jt)) * ct[c, CT_KN]
            if change > moving:
                moved = True
                now[a] = mark
                if b >= 0:
                    now[b] = mark
            residual = max(residual, change)
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
        if full:
            done += 1
            if residual <= tol:
                break
            partial = 0
        else:
            partial += 1
        if used >= budget:
            break
        full = not moved or partial >= PARTIAL_SWEEPS
    for c in range(nc):
        prev[c, PV_KA] = ct[c, CT_KA]
        prev[c, PV_KB] = ct[c, CT_KB]
        prev[c, PV_LN] = ct[c, CT_LN]
        prev[c, PV_LT] = ct[c, CT_LT]
    prev[prev.shape[0] - 1, 0] = nc
    return done


@njit(cache=True)
def correct_positions(nc, ct, cidx, ptype, x, y, x0, y0, pt, passes, mp):
    """Push overlapping bodies apart along the contact normals (translation only).

    The depth of each contact is estimated from its detected depth and how far its bodies
    moved since (``x0``, ``y0``: positions at detection); each of ``passes`` sweeps removes
    ``mp[MP_CORRECTION]`` of the excess over the slop, in inverse-mass proportion (a fixed or
    kinematic body does not move), so the centre of mass stays. Velocities are not touched: the
    correction neither changes momentum nor adds kinetic energy. The shares come from
    :func:`prepare_contacts` (no division in the chain).
    """
    slop = mp[MP_SLOP]
    for it in range(passes):
        # branch-free per contact, as in solve_impulses (no excess: a zero move)
        for c in range(nc):
            a = cidx[c, 0]
            b = cidx[c, 1]
            nx = ct[c, CT_NX]
            ny = ct[c, CT_NY]
            moved = nx * (x[a] - x0[a]) + ny * (y[a] - y0[a])
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


