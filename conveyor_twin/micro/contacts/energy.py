"""The energy limit of the impulse model: no island of parts gains more kinetic energy in a
substep than the external work done on it.

Every sweep of :func:`conveyor_twin.micro.contacts.impulses.solve_impulses` and
:func:`conveyor_twin.micro.contacts.restitution.restitute` keeps momentum, but kinetic energy
can rise (a warm start's stale impulse pushing apart bodies that no longer press on each other,
an increment taking back impulse from a contact that still closes), so :func:`limit_energy`
scales the substep's impulses of each island (parts joined by contacts), if needed, so its
parts' kinetic energy does not rise by more than the external work on them (belt friction,
moving actuators).
"""

from numba import njit

from conveyor_twin.micro.contacts.tables import (CT_BVX, CT_BVY, CT_BW, CT_LN, CT_LT, CT_NX,
                                                 CT_NY, CT_RBX, CT_RBY, PV_LN, PV_LT)
from conveyor_twin.micro.state import PT_INERTIA, PT_MASS


@njit(cache=True, inline='always')
def island_root(parent, i):
    """Return the representative of part ``i``'s island (union-find with path halving); a
    representative may be marked by holding ``-1 - itself`` (the restitution's held islands).
    """
    while True:
        p = parent[i]
        if p == i or p < 0:
            return i
        g = parent[p]
        if g >= 0:
            parent[i] = g
        i = p


@njit(cache=True, inline='always')
def _energy_change(i, ptype, pt, vx, vy, wz, v0x, v0y, w0):
    """Return part ``i``'s kinetic energy change from ``v0`` to ``v`` as ``(g, q)`` [J]:
    ``g = m v0 . dv + I w0 dw`` (linear in the change), ``q = (m dv^2 + I dw^2) / 2``."""
    t = ptype[i]
    dx = vx[i] - v0x[i]
    dy = vy[i] - v0y[i]
    dw = wz[i] - w0[i]
    mi = pt[t, PT_MASS]
    ii = pt[t, PT_INERTIA]
    return (mi * (v0x[i] * dx + v0y[i] * dy) + ii * w0[i] * dw,
            0.5 * (mi * (dx * dx + dy * dy) + ii * dw * dw))


@njit(cache=True)
def limit_energy(n, nc, ptype, pt, v, v0, heat, contacts):
    """Scale each island's contact impulses of the substep so its parts' kinetic energy does
    not rise by more than the external work done on them in the substep.

    The bound is the first law for the island: kinetic energy rises by at most the work of the
    surroundings (dissipation >= 0). External work: the belts' and the floor's surface friction
    (``heat``: what it dissipated in this substep beyond the kinetic energy it gave, from
    :func:`~conveyor_twin.micro.drive.belt_drive`; ``v0`` holds the velocities after it)
    and the moving actuators. Without either (a belt at rest under parts at rest, walls only)
    the island's kinetic energy never rises.

    An island is a set of parts joined by contacts (fixed and kinematic bodies join nothing);
    islands do not exchange impulses, so each is limited alone and a jam does not touch parts
    elsewhere. ``v0 = (v0x, v0y, w0)``: the velocities before the warm start of
    :func:`~conveyor_twin.micro.contacts.impulses.prepare_contacts`. All of an island's
    impulses together changed them by ``dv``; scaled by ``s`` its kinetic energy changes by
    ``s g + s^2 q`` (``g = sum m v0 . dv + I w0 dw``, ``q = sum (m dv^2 + I dw^2) / 2``). A
    kinematic body moving at ``u`` at a contact does the work ``s W``, ``W = sum J . u`` over
    its contacts' impulses ``J`` on the parts (a contact that does not add energy in the body's
    frame adds at most that in ours; fixed bodies: ``u = 0``). If ``g + q > W + H`` (``H`` the
    island's heat; a warm start pushed apart bodies that no longer press on each other, or
    friction let go of what it held) ``s`` is taken as ``(W + H - g) / q`` (0 if that is
    negative), which keeps ``s g + s^2 q <= s W + H``, and the island's impulses kept for the
    next warm start are scaled alike. Every impulse keeps its partner, so momentum stays.

    :param v: ``(vx, vy, wz)``: the velocities after the impulses [m/s, rad/s], scaled here.
    :param contacts: the contacts group of :func:`conveyor_twin.micro.kernel.run_steps`; read
        here: the records ``ct``, ``cidx`` and ``prev``, and the scratch ``island``
        (int64[capacity], the islands) and ``island_sums`` ((3, capacity)).
    :return: number of islands scaled.
    """
    vx, vy, wz = v
    v0x, v0y, w0 = v0
    _va, _vb, _out, ct, cidx, _acc, prev, parent, acc3 = contacts
    # the external work, per part: the heat of the surface friction and the moving actuators'
    for i in range(n):
        acc3[2, i] = heat[i]
    c = nc - 1
    while c >= 0 and cidx[c, 1] < 0:      # contacts with fixed and kinematic bodies come last
        bw = ct[c, CT_BW]
        ubx = ct[c, CT_BVX] - bw * ct[c, CT_RBY]
        uby = ct[c, CT_BVY] + bw * ct[c, CT_RBX]
        if ubx != 0.0 or uby != 0.0:
            nx = ct[c, CT_NX]
            ny = ct[c, CT_NY]
            ln = ct[c, CT_LN]
            lt = ct[c, CT_LT]
            acc3[2, cidx[c, 0]] += (ln * nx - lt * ny) * ubx + (ln * ny + lt * nx) * uby
        c -= 1
    # each part's energy change less that work: if none is positive, no island's sum is
    rising = False
    for i in range(n):
        g, q = _energy_change(i, ptype, pt, vx, vy, wz, v0x, v0y, w0)
        if g + q > acc3[2, i]:
            rising = True
            break
    if not rising:
        return 0
    for i in range(n):
        parent[i] = i
        acc3[0, i] = 0.0
        acc3[1, i] = 0.0
    for c in range(nc):
        b = cidx[c, 1]
        if b >= 0:
            ra = island_root(parent, cidx[c, 0])
            rb = island_root(parent, b)
            if ra != rb:
                # the smaller index represents (deterministic, independent of other islands)
                if ra < rb:
                    parent[rb] = ra
                else:
                    parent[ra] = rb
    # sums per island, on its representative (the work was summed per part above)
    for i in range(n):
        g, q = _energy_change(i, ptype, pt, vx, vy, wz, v0x, v0y, w0)
        r = island_root(parent, i)
        parent[i] = r
        acc3[0, r] += g
        acc3[1, r] += q
        if r != i:
            acc3[2, r] += acc3[2, i]
            acc3[2, i] = 0.0
    scaled = 0
    for i in range(n):
        if parent[i] == i:
            g = acc3[0, i]
            q = acc3[1, i]
            work = acc3[2, i]
            s = 1.0
            if g + q > work and q > 0.0:
                s = max((work - g) / q, 0.0)
                scaled += 1
            acc3[0, i] = s
    if scaled == 0:
        return 0
    for i in range(n):
        s = acc3[0, parent[i]]     # paths are compressed to the root by the loop above
        if s != 1.0:
            vx[i] = v0x[i] + s * (vx[i] - v0x[i])
            vy[i] = v0y[i] + s * (vy[i] - v0y[i])
            wz[i] = w0[i] + s * (wz[i] - w0[i])
    for c in range(nc):
        s = acc3[0, parent[cidx[c, 0]]]
        if s != 1.0:
            prev[c, PV_LN] *= s
            prev[c, PV_LT] *= s
    return scaled
