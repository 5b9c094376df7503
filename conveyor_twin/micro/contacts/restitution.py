"""The impulse model's sweep order and its restitution pass.

Restitution in its own pass after the velocity sweeps (Box2D v3's ``b2ApplyRestitution``):
the sweeps of :func:`~.impulses.solve_impulses` stop every contact (plastic, or closing a
speculative gap exactly); then

1. every contact whose approach arose within the substep (approach before it at most
   :data:`RESTITUTION_THRESHOLD`, so ``CT_BOUNCE`` is 0: a disc struck in this substep pushing
   its touching neighbour) and that carried no impulse the substep before (no warm start: a
   jam's contacts, pressed from substep to substep, never bounce) gets Poisson's restitution
   impulse in one pass: ``e`` times its impact impulse, the normal impulse of the sweeps plus
   what closing a speculative gap left out (``-target / k_n``), if that impulse changed its
   relative speed by more than the threshold. With ``e = 1`` and no friction this returns the
   kinetic energy the converged sweeps took (``dKE = 2 P . J v = 0`` where they left
   ``J v = 0``);
2. every contact that bounces (approach speed before the substep above the threshold) and
   carried an impulse is driven to its bounce, ``u_n = e |u_n0|`` from the normal speed
   ``u_n0`` stored before any impulse of the substep. All bouncing contacts aim at their own
   stored speed together, so contacts that happen at once keep their restitution whatever the
   order. The pass is swept, alternating forward and backward, until its increments fall
   below ``mp[MP_BOUNCE_TOLERANCE]`` (at most ``mp[MP_BOUNCE_PASSES]`` sweeps): its end state
   depends only on the velocities before the substep, not on how far the velocity sweeps got,
   so a symmetric impact stays symmetric. It visits only the bouncing contacts (listed once),
   so a tight tolerance costs little.

An impact within the substep starts from a contact that approached before it, so the kernel
calls :func:`restitute` only in substeps with a bouncing contact.
"""

from numba import njit

from conveyor_twin.micro.contacts.tables import (CT_BOUNCE, CT_BVX, CT_BVY, CT_BW, CT_CNT,
                                                 CT_E, CT_IKN, CT_KN, CT_LN, CT_LN0, CT_LT,
                                                 CT_MU_K,
                                                 CT_MU_S, CT_NX, CT_NY, CT_RAX, CT_RAY,
                                                 CT_RBX, CT_RBY, CT_SLOPE, CT_TARGET, CT_V_T,
                                                 MP_BOUNCE_PASSES, MP_BOUNCE_TOLERANCE)
from conveyor_twin.micro.state import PT_INV_INERTIA, PT_INV_MASS

# Below this approach speed [m/s] a contact is treated as plastic (no bounce).
RESTITUTION_THRESHOLD = 0.02


@njit(cache=True, inline='always')
def sweep_plan(nc, cidx):
    """Return the sweep order's constants: the number of part-part contacts (they come first),
    half of it rounded up, and the number of visits of a sweep."""
    pairs = nc
    while pairs > 0 and cidx[pairs - 1, 1] < 0:
        pairs -= 1
    half = (pairs + 1) // 2
    return pairs, half, 2 * half + nc - pairs


@njit(cache=True, inline='always')
def sweep_contact(k, pairs, half):
    """Return the contact of a sweep's ``k``-th visit, or -1 for none.

    The part-part contacts' two halves alternate (``0, h, 1, h + 1, ...``), then the contacts
    with fixed and kinematic bodies follow in order. Consecutive contacts of a half often share
    a body, so each one's impulse waits for the one before; the other half's contact in between
    is far away (the canonical order follows the parts' slots), so the processor works on both
    at once. A backward sweep visits ``k`` from the last visit down.
    """
    if k < 2 * half:
        c = (k & 1) * half + (k >> 1)
        return c if c < pairs else -1
    return pairs + k - 2 * half


@njit(cache=True, inline='always')
def _bounce(c, ct, cidx, ptype, vx, vy, wz, pt):
    """Drive contact ``c`` to its bounce speed; return the change of its relative speed."""
    a = cidx[c, 0]
    b = cidx[c, 1]
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
    ux = (vax - wa * ray) - (vbx - wb * rby)
    uy = (vay + wa * rax) - (vby + wb * rbx)
    un = ux * nx + uy * ny
    ln = ct[c, CT_LN]
    ln1 = max(ln + (ct[c, CT_BOUNCE] - un) * ct[c, CT_IKN], 0.0)
    jn = ln1 - ln
    # where the normal impulse shrinks, the tangential one stays inside the new cone
    ut = (uy * nx - ux * ny) + jn * ct[c, CT_CNT]
    speed = abs(ut)
    mu = (ct[c, CT_MU_S] + ct[c, CT_SLOPE] * speed if speed < ct[c, CT_V_T]
          else ct[c, CT_MU_K])
    limit = mu * ln1
    lt = ct[c, CT_LT]
    lt1 = min(max(lt, -limit), limit)
    jt = lt1 - lt
    ct[c, CT_LN] = ln1
    ct[c, CT_LT] = lt1
    px = jn * nx - jt * ny
    py = jn * ny + jt * nx
    vx[a] = vax + px * ima
    vy[a] = vay + py * ima
    wz[a] = wa + iia * (rax * py - ray * px)
    if b >= 0:
        vx[b] = vbx - px * imb
        vy[b] = vby - py * imb
        wz[b] = wb - iib * (rbx * py - rby * px)
    return (abs(jn) + abs(jt)) * ct[c, CT_KN]


@njit(cache=True, inline='always')
def _poisson(c, ct, cidx, ptype, vx, vy, wz, pt):
    """Apply Poisson's restitution impulse to contact ``c`` (see the module docstring): if it
    has no warm start, ``e`` times its impact impulse [N s] along its normal, at the contact
    point, equal and opposite, if the impact impulse changed its relative normal speed by more
    than :data:`RESTITUTION_THRESHOLD`; the tangential impulse stays (the cone only widens)."""
    ln = ct[c, CT_LN]
    p = ln - ct[c, CT_TARGET] * ct[c, CT_IKN]
    if ct[c, CT_LN0] != 0.0 or ln <= 0.0 or p * ct[c, CT_KN] <= RESTITUTION_THRESHOLD:
        return
    jn = ct[c, CT_E] * p
    ct[c, CT_LN] = ln + jn
    a = cidx[c, 0]
    b = cidx[c, 1]
    px = jn * ct[c, CT_NX]
    py = jn * ct[c, CT_NY]
    ta = ptype[a]
    ima = pt[ta, PT_INV_MASS]
    vx[a] += px * ima
    vy[a] += py * ima
    wz[a] += pt[ta, PT_INV_INERTIA] * (ct[c, CT_RAX] * py - ct[c, CT_RAY] * px)
    if b >= 0:
        tb = ptype[b]
        imb = pt[tb, PT_INV_MASS]
        vx[b] -= px * imb
        vy[b] -= py * imb
        wz[b] -= pt[tb, PT_INV_INERTIA] * (ct[c, CT_RBX] * py - ct[c, CT_RBY] * px)


@njit(cache=True)
def restitute(nc, ct, cidx, ptype, vx, vy, wz, pt, mp, order):
    """Give the contacts whose impact arose within the substep Poisson's restitution impulse,
    then drive every bouncing contact that carried an impulse to its bounce speed
    (``CT_BOUNCE``) in sweeps (see the module docstring); return the number of sweeps (0:
    nothing bounces).

    The accumulated normal impulse stays >= 0; where it shrinks, the accumulated tangential
    one is clamped to the new Coulomb cone (the friction coefficient at the current sliding
    speed). Equal and opposite impulses at the contact point: momentum is kept.

    :param order: int64 scratch: the bouncing contacts in the sweep order (when there are
        more than it holds, the sweeps walk all contacts and skip the others).
    """
    tol = mp[MP_BOUNCE_TOLERANCE]
    passes = int(mp[MP_BOUNCE_PASSES])
    pairs, half, visits = sweep_plan(nc, cidx)
    # only the contacts that carried an impulse in the velocity sweeps bounce
    m = 0
    for k in range(visits):
        c = sweep_contact(k, pairs, half)
        if c < 0:
            continue
        if ct[c, CT_LN] == 0.0:
            ct[c, CT_BOUNCE] = 0.0
        elif ct[c, CT_BOUNCE] == 0.0:
            _poisson(c, ct, cidx, ptype, vx, vy, wz, pt)
        else:
            if m < order.shape[0]:
                order[m] = c
            m += 1
    if m == 0:
        return 0
    listed = m <= order.shape[0]
    done = 0
    for it in range(passes):
        residual = 0.0
        if listed:
            for kk in range(m):
                c = order[kk if it % 2 == 0 else m - 1 - kk]
                residual = max(residual, _bounce(c, ct, cidx, ptype, vx, vy, wz, pt))
        else:
            for kk in range(visits):
                c = sweep_contact(kk if it % 2 == 0 else visits - 1 - kk, pairs, half)
                if c >= 0 and ct[c, CT_BOUNCE] != 0.0:
                    residual = max(residual, _bounce(c, ct, cidx, ptype, vx, vy, wz, pt))
        done = it + 1
        if residual <= tol:
            break
    return done
