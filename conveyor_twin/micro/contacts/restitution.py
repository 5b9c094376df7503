"""The impulse model's sweep order, the restitution's per-contact step and its pass.

Restitution in a pass of its own after the velocity sweeps (as Box2D v3's
``b2ApplyRestitution``): the sweeps of :func:`~.impulses.solve_impulses` stop every contact
(plastic, or closing a speculative gap exactly); then every contact that carried an impulse in
them and approached faster than :data:`RESTITUTION_THRESHOLD` bounces, by one of two rules.

An *impact* is such a contact that carried no impulse the substep before (no warm start) and
has ``e > 0``; it approached before the substep (``CT_BOUNCE > 0``) or within it (a disc
struck in this substep meeting its neighbour: the impact impulse, the sweeps' normal impulse
plus what closing a speculative gap left out, ``-target / k_n``, changed its relative speed by
more than the threshold). The parts joined by contacts that carry an impulse form islands; an
island is *held* if one of those contacts has a warm start (a jam, a queue: pressed from
substep to substep, its compression impulses carry that load) or is with a moving actuator
(which may drive its parts into a wall: the compression has no bound), else *free*.

1. Poisson's restitution, in free islands: their impacts are swept on as touching contacts
   (target ``u_n = 0``, gaps closed; the island's other contacts keep their impulses) until
   the increments fall below ``mp[MP_BOUNCE_TOLERANCE]`` (at most ``mp[MP_BOUNCE_PASSES]``
   sweeps), which gives their compression impulses ``P``; then each gets ``e P`` more along
   its normal. With ``e = 1`` and no friction this keeps the kinetic energy however many
   impacts happen at once and in whatever order they would have happened within the substep
   (``dKE = 2 P . J v = 0`` where the compression left ``J v = 0``, ``P = 0`` elsewhere); an
   isolated impact gets Hoher et al.'s ``j = -(1 + e) u_n / k_n``. The compression converges
   to a tight tolerance from the velocity sweeps' state, so its end state does not depend on
   how far those got and a symmetric impact stays symmetric. An impact leaves no warm start
   for the next substep (it is over), so a cluster that keeps colliding stays free.
2. In held islands the bounce follows the approach instead: an impact struck within the
   substep gets ``e`` times its impact impulse once, and every contact that approached before
   the substep is driven to its bounce, ``u_n = e |u_n0|`` from the normal speed ``u_n0``
   stored before any impulse of the substep (a jam's contacts, warm started, are no impacts
   and never bounce). These aim at their own stored speed together, in sweeps
   alternating forward and backward until their increments fall below
   ``mp[MP_BOUNCE_TOLERANCE]`` (at most ``mp[MP_BOUNCE_PASSES]``).

Both sweeps visit only their own contacts (listed once), so a tight tolerance costs little. An
impact within the substep starts from a contact that approached before it, so the kernel calls
:func:`restitute` only in substeps with a bouncing contact.
"""

from numba import njit

from conveyor_twin.micro.contacts.energy import island_root
from conveyor_twin.micro.contacts.tables import (CT_BOUNCE, CT_BVX, CT_BVY, CT_BW, CT_CNT,
                                                 CT_E, CT_IKN, CT_IKT, CT_KN, CT_LN, CT_LN0,
                                                 CT_LT, CT_MU_K, CT_MU_S, CT_NX, CT_NY, CT_RAX,
                                                 CT_RAY, CT_RBX, CT_RBY, CT_SLOPE, CT_TARGET,
                                                 CT_V_T, MP_BOUNCE_PASSES, MP_BOUNCE_TOLERANCE,
                                                 PV_LN, PV_LT)
from conveyor_twin.micro.state import PT_INV_INERTIA, PT_INV_MASS

# Below this approach speed [m/s] a contact is treated as plastic (no bounce).
RESTITUTION_THRESHOLD = 0.02

# CT_BOUNCE of an impact during :func:`restitute` (a bounce speed is >= 0)
_IMPACT = -1.0


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
def contact_step(c, ct, cidx, ptype, vx, vy, wz, pt, target, slide):
    """Apply one sweep increment of contact ``c``; return ``(j_n, j_t, u_t)``: the increments
    of its normal and tangential impulses [N s] and its sliding speed [m/s] after ``j_n``.

    The accumulated normal impulse, kept >= 0, brings the relative normal speed to ``target``
    [m/s]; the accumulated tangential one is clamped to the Coulomb cone of the new normal one
    (the friction coefficient at that sliding speed), after stopping the sliding if ``slide``
    (the compression of the impacts; the bounce only keeps it inside the cone). Both act on
    both bodies, equal and opposite, at the contact point. The tangential speed after the
    normal impulse follows algebraically (``CT_CNT``), which keeps the chain from one contact
    to the next short. :func:`~.impulses.solve_impulses` does the same arithmetic (with
    ``slide``) in its own loop: called through this function, its compiled loop ran 2.7 times
    slower.
    """
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
    ln1 = max(ln + (target - un) * ct[c, CT_IKN], 0.0)
    jn = ln1 - ln
    ut = (uy * nx - ux * ny) + jn * ct[c, CT_CNT]
    speed = abs(ut)
    mu = (ct[c, CT_MU_S] + ct[c, CT_SLOPE] * speed if speed < ct[c, CT_V_T]
          else ct[c, CT_MU_K])
    limit = mu * ln1
    lt = ct[c, CT_LT]
    if slide:
        lt1 = min(max(lt - ut * ct[c, CT_IKT], -limit), limit)
    else:
        lt1 = min(max(lt, -limit), limit)
    jt = lt1 - lt
    ct[c, CT_LN] = ln1
    ct[c, CT_LT] = lt1
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
    return jn, jt, ut


@njit(cache=True, inline='always')
def _sweep(c, ct, cidx, ptype, vx, vy, wz, pt, impacts):
    """Sweep contact ``c`` of a restitution pass: compress an impact (target 0) or drive a
    bounce to ``CT_BOUNCE``; return the change of its relative speed [m/s]."""
    if impacts:
        jn, jt, _ut = contact_step(c, ct, cidx, ptype, vx, vy, wz, pt, 0.0, True)
    else:
        jn, jt, _ut = contact_step(c, ct, cidx, ptype, vx, vy, wz, pt, ct[c, CT_BOUNCE], False)
    return (abs(jn) + abs(jt)) * ct[c, CT_KN]


@njit(cache=True, inline='always')
def _kick(c, ct, cidx, ptype, vx, vy, wz, pt, jn):
    """Add the normal impulse ``jn`` [N s] to contact ``c``, at the contact point, equal and
    opposite; the tangential impulse stays (the cone only widens)."""
    ct[c, CT_LN] += jn
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


@njit(cache=True, inline='always')
def _impact(c, ct):
    """Return whether contact ``c`` is an impact (see the module docstring) and its impact
    impulse [N s] (the sweeps' normal impulse plus what closing a gap left out)."""
    ln = ct[c, CT_LN]
    p = ln - ct[c, CT_TARGET] * ct[c, CT_IKN]
    return (ln > 0.0 and ct[c, CT_LN0] == 0.0 and ct[c, CT_E] > 0.0
            and (ct[c, CT_BOUNCE] > 0.0 or p * ct[c, CT_KN] > RESTITUTION_THRESHOLD)), p


@njit(cache=True)
def _islands(visits, pairs, half, ct, cidx, parent):
    """Join the parts of the contacts that carry an impulse into islands in ``parent`` (read
    with :func:`~.energy.island_root`) and mark the held ones (see the module docstring)."""
    for k in range(visits):
        c = sweep_contact(k, pairs, half)
        if c >= 0 and ct[c, CT_LN] > 0.0:
            parent[cidx[c, 0]] = cidx[c, 0]
            if cidx[c, 1] >= 0:
                parent[cidx[c, 1]] = cidx[c, 1]
    for c in range(pairs):
        if ct[c, CT_LN] > 0.0:
            ra = island_root(parent, cidx[c, 0])
            rb = island_root(parent, cidx[c, 1])
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    for k in range(visits):
        c = sweep_contact(k, pairs, half)
        if c >= 0 and ct[c, CT_LN] > 0.0 and (ct[c, CT_LN0] != 0.0 or (cidx[c, 1] < 0 and (
                ct[c, CT_BVX] != 0.0 or ct[c, CT_BVY] != 0.0 or ct[c, CT_BW] != 0.0))):
            r = island_root(parent, cidx[c, 0])
            parent[r] = -1 - r


@njit(cache=True, inline='always')
def _passes(nc, ct, cidx, ptype, vx, vy, wz, pt, mp, order, lists):
    """Sweep the impacts of free islands (``impacts`` true: ``order[:m]``) or the bouncing
    contacts of held ones (``order[-nb:]``, from the end) to the tolerance; return the number
    of sweeps.

    :param lists: ``(m, nb, listed, impacts)``; not ``listed`` (more than ``order`` holds):
        the sweeps walk all contacts and visit those marked in ``CT_BOUNCE``.
    """
    m, nb, listed, impacts = lists
    tol = mp[MP_BOUNCE_TOLERANCE]
    count = m if impacts else nb
    last = order.shape[0] - 1
    pairs, half, visits = sweep_plan(nc, cidx)
    done = 0
    for it in range(int(mp[MP_BOUNCE_PASSES])):
        residual = 0.0
        if listed:
            for kk in range(count):
                k = kk if it % 2 == 0 else count - 1 - kk
                c = order[k] if impacts else order[last - k]
                residual = max(residual, _sweep(c, ct, cidx, ptype, vx, vy, wz, pt, impacts))
        else:
            for kk in range(visits):
                c = sweep_contact(kk if it % 2 == 0 else visits - 1 - kk, pairs, half)
                if c >= 0 and (ct[c, CT_BOUNCE] == _IMPACT if impacts
                               else ct[c, CT_BOUNCE] > 0.0):
                    residual = max(residual, _sweep(c, ct, cidx, ptype, vx, vy, wz, pt, impacts))
        done = it + 1
        if residual <= tol:
            break
    return done


@njit(cache=True)
def restitute(nc, ct, cidx, ptype, vx, vy, wz, pt, mp, order, prev):
    """Give the impacts of free islands Poisson's restitution on their converged compression,
    the bouncing contacts of held islands their bounce from the approach (see the module
    docstring); return the number of sweeps (0: nothing bounces).

    The accumulated normal impulse stays >= 0; the accumulated tangential one stays in the
    Coulomb cone of the normal one (the friction coefficient at the current sliding speed).
    Equal and opposite impulses at the contact point: momentum is kept.

    :param order: int64 scratch, at least one entry per part: first the islands, then the
        impacts of free islands from its start and the other bouncing contacts from its end,
        each in the sweep order (when there are more than it holds, the sweeps walk all
        contacts and visit those marked in ``CT_BOUNCE``).
    :param prev: the next substep's warm start (:func:`~.impulses.solve_impulses`); an impact
        that got Poisson's restitution leaves none.
    """
    pairs, half, visits = sweep_plan(nc, cidx)
    any_impact = False
    for k in range(visits):
        c = sweep_contact(k, pairs, half)
        if c >= 0:
            if ct[c, CT_LN] == 0.0:
                ct[c, CT_BOUNCE] = 0.0
            elif not any_impact:
                any_impact = _impact(c, ct)[0]
    if any_impact:
        _islands(visits, pairs, half, ct, cidx, order)
    # mark the impacts of free islands, give the impacts of held islands struck within the
    # substep their impulse
    for k in range(visits):
        c = sweep_contact(k, pairs, half)
        if c < 0 or ct[c, CT_LN] == 0.0:
            continue
        impact, p = _impact(c, ct)
        if not impact:
            continue
        if order[island_root(order, cidx[c, 0])] >= 0:
            ct[c, CT_BOUNCE] = _IMPACT
        elif ct[c, CT_BOUNCE] == 0.0:
            _kick(c, ct, cidx, ptype, vx, vy, wz, pt, ct[c, CT_E] * p)
    cap = order.shape[0]
    m = 0
    nb = 0
    for k in range(visits):
        c = sweep_contact(k, pairs, half)
        if c < 0:
            continue
        if ct[c, CT_BOUNCE] == _IMPACT:
            if m + nb < cap:
                order[m] = c
            m += 1
        elif ct[c, CT_BOUNCE] > 0.0:
            if m + nb < cap:
                order[cap - 1 - nb] = c
            nb += 1
    listed = m + nb <= cap
    done = 0
    if m > 0:
        done += _passes(nc, ct, cidx, ptype, vx, vy, wz, pt, mp, order, (m, nb, listed, True))
        for k in range(m if listed else visits):
            c = order[k] if listed else sweep_contact(k, pairs, half)
            if c >= 0 and ct[c, CT_BOUNCE] == _IMPACT:
                _kick(c, ct, cidx, ptype, vx, vy, wz, pt, ct[c, CT_E] * ct[c, CT_LN])
                # the impact is over: no warm start from it
                prev[c, PV_LN] = 0.0
                prev[c, PV_LT] = 0.0
    if nb > 0:
        done += _passes(nc, ct, cidx, ptype, vx, vy, wz, pt, mp, order, (m, nb, listed, False))
    return done
