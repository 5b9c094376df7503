"""Slow, readable reference of the contact kernel (near phase and impulse sweeps).

Plain Python and numpy, written for clarity, not speed; the tests check the compiled kernels
of :mod:`conveyor_twin.micro.collide` and :mod:`conveyor_twin.micro.contacts` against it.
Shapes are ``(core vertices (nv, 2) [m], radius [m])`` as in ``collide``.
"""

import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.micro.contacts.impulses import MOVING_SHARE, PARTIAL_SWEEPS

Contact = Tuple[np.ndarray, float]   # (unit normal from B to A, depth [m])


def _closest_on_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    denom = ab @ ab
    t = 0.0 if denom == 0.0 else min(max((p - a) @ ab / denom, 0.0), 1.0)
    return a + t * ab


def _edges(verts: np.ndarray):
    for i in range(len(verts)):
        yield verts[i], verts[(i + 1) % len(verts)]


def _inside(p: np.ndarray, verts: np.ndarray) -> bool:
    """True if p is inside the convex counter-clockwise polygon."""
    if len(verts) < 3:
        return False
    return all((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]) > 0.0
               for a, b in _edges(verts))


def _point_core(p: np.ndarray, verts: np.ndarray) -> Tuple[np.ndarray, float, bool]:
    """Return (closest core point, distance, p inside the core)."""
    if len(verts) == 1:
        return verts[0], float(np.linalg.norm(p - verts[0])), False
    best = None
    for a, b in _edges(verts) if len(verts) > 2 else [(verts[0], verts[1])]:
        q = _closest_on_segment(p, a, b)
        d = float(np.linalg.norm(p - q))
        if best is None or d < best[1]:
            best = (q, d)
    return best[0], best[1], _inside(p, verts)


def _axes(verts: np.ndarray) -> List[np.ndarray]:
    out = []
    pairs = list(_edges(verts)) if len(verts) > 2 else [(verts[0], verts[1]),
                                                        (verts[1], verts[0])]
    for a, b in pairs:
        e = b - a
        out.append(np.array([e[1], -e[0]]) / np.linalg.norm(e))
    return out


def collide_ref(a: Tuple[np.ndarray, float], b: Tuple[np.ndarray, float]) -> Optional[Contact]:
    """Return the deepest contact of two rounded convex shapes, or None if they do not touch.

    Separated cores: the closest points of the cores, depth = radii - distance. Overlapping
    cores (boxes, polygons): the separating-axis test over every edge normal, depth = least
    overlap along an axis + radii.
    """
    (va, ra), (vb, rb) = a, b
    va = np.asarray(va, dtype=float)
    vb = np.asarray(vb, dtype=float)
    if len(va) == 1 or len(vb) == 1:
        flip = len(va) != 1
        p, core, r = (vb[0], va, ra + rb) if flip else (va[0], vb, ra + rb)
        q, d, inside = _point_core(p, core)
        if inside:
            # least exit through a face: the largest (least negative) face separation
            separation, normal = max((((p - e0) @ n, n) for (e0, _), n in
                                      zip(_edges(core), _axes(core))), key=lambda sn: sn[0])
            depth = r - separation
        else:
            if d >= r:
                return None
            normal = (p - q) / d if d > 0 else np.array([1.0, 0.0])
            depth = r - d
        return (-normal if flip else normal), float(depth)
    # polygon-polygon: distance between cores if apart
    segs_a = list(_edges(va)) if len(va) > 2 else [(va[0], va[1])]
    segs_b = list(_edges(vb)) if len(vb) > 2 else [(vb[0], vb[1])]
    best = None
    for a0, a1 in segs_a:
        for b0, b1 in segs_b:
            for p, s0, s1, sign in ((a0, b0, b1, 1.0), (a1, b0, b1, 1.0),
                                    (b0, a0, a1, -1.0), (b1, a0, a1, -1.0)):
                q = _closest_on_segment(p, s0, s1)
                d = float(np.linalg.norm(p - q))
                if best is None or d < best[0]:
                    best = (d, sign * (p - q))
    apart = not any(_inside(p, vb) for p in va) and not any(_inside(p, va) for p in vb) and \
        best[0] > 1e-9 and not _segments_cross(segs_a, segs_b)
    if apart:
        if best[0] >= ra + rb:
            return None
        return best[1] / best[0], float(ra + rb - best[0])
    # overlapping cores: SAT
    least = None
    for axis in _axes(va) + _axes(vb):
        pa = va @ axis
        pb = vb @ axis
        overlap = min(pa.max() - pb.min(), pb.max() - pa.min())
        if least is None or overlap < least[0]:
            # normal from B to A along the axis
            sign = 1.0 if pa.mean() - pb.mean() >= 0.0 else -1.0
            least = (overlap, sign * axis)
    return least[1], float(least[0] + ra + rb)


def _segments_cross(segs_a, segs_b) -> bool:
    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])
    for a0, a1 in segs_a:
        for b0, b1 in segs_b:
            if (orient(a0, a1, b0) * orient(a0, a1, b1) < 0
                    and orient(b0, b1, a0) * orient(b0, b1, a1) < 0):
                return True
    return False


def friction_ref(mu_s: float, mu_k: float, v_t: float, speed: float) -> float:
    """Horváth et al.: static at rest, sliding from ``v_t`` on, linear in between."""
    return mu_k if speed >= v_t else mu_s + (mu_k - mu_s) * speed / v_t


def cross(r: np.ndarray, v: np.ndarray) -> float:
    """z of the planar cross product."""
    return float(r[0] * v[1] - r[1] * v[0])


def sweeps_ref(contacts: Sequence[dict], v: np.ndarray, w: np.ndarray, m_inv: np.ndarray,
               i_inv: np.ndarray, passes: int, heat: Optional[np.ndarray] = None, *,
               h: float, tolerance: float, bounce_passes: int,
               bounce_tolerance: float, work: int = 0, max_passes: int = 0,
               stats: Optional[dict] = None) -> List[Tuple[float, float]]:
    """Apply the impulses of :func:`conveyor_twin.micro.contacts.impulses.prepare_contacts`,
    :func:`~conveyor_twin.micro.contacts.impulses.solve_impulses`,
    :func:`~conveyor_twin.micro.contacts.restitution.restitute` and
    :func:`~conveyor_twin.micro.contacts.energy.limit_energy`; return the accumulated
    (normal, tangential) impulse of each contact kept for the next substep (before the
    restitution sweeps, scaled by the energy limit).

    :param contacts: dicts with ``a``, ``b`` (-1: fixed), ``n``, ``ra``, ``rb``, ``e``,
        ``mu_s``, ``mu_k``, ``v_t``, ``bv``, ``bw``, ``depth`` (< 0: a speculative contact's
        gap) and the warm start ``ln``, ``lt`` (the previous substep's impulses, 0 for a new
        contact). :param h: the substep [s]; ``tolerance``, ``bounce_passes``,
        ``bounce_tolerance``: the sweeps' stopping rules. :param passes: the least impulse
        sweeps; ``work`` contact visits buy more, up to ``max_passes`` (0: ``passes`` only).
    :param v: (n, 2) velocities, in place.
    :param heat: (n,) what surface friction dissipated on each part in the substep [J] (the
        external work an island may turn into kinetic energy; zeros if None).
    :param stats: filled, if given, with the impulse sweeps' ``full_sweeps``, ``sweeps`` (full
        and partial), ``visits`` (contacts visited) and ``partial_visits`` (in partial sweeps).
    """
    stats = {} if stats is None else stats
    stats['partial_visits'] = 0
    v0, w0 = v.copy(), w.copy()

    def body(c, side):
        k = c[side]
        if k < 0:
            return np.array(c['bv'], dtype=float), float(c['bw']), 0.0, 0.0
        return v[k], w[k], m_inv[k], i_inv[k]

    def relative(c):
        va, wa, _, _ = body(c, 'a')
        vb, wb, _, _ = body(c, 'b')
        ra, rb = c['ra'], c['rb']
        return (va + wa * np.array([-ra[1], ra[0]])) - (vb + wb * np.array([-rb[1], rb[0]]))

    def apply(c, impulse):
        a, b = c['a'], c['b']
        v[a] += impulse * m_inv[a]
        w[a] += i_inv[a] * cross(c['ra'], impulse)
        if b >= 0:
            v[b] -= impulse * m_inv[b]
            w[b] -= i_inv[b] * cross(c['rb'], impulse)

    def inverse_mass(c, d):
        k = m_inv[c['a']] + i_inv[c['a']] * cross(c['ra'], d) ** 2
        if c['b'] >= 0:
            k += m_inv[c['b']] + i_inv[c['b']] * cross(c['rb'], d) ** 2
        return k

    # bounce from the approach before any impulse
    bounce = []
    for c in contacts:
        un = relative(c) @ c['n']
        bounce.append(c['e'] * -un if -un > 0.02 else 0.0)
    # warm start
    acc = []
    for c in contacts:
        n = np.asarray(c['n'], dtype=float)
        t = np.array([-n[1], n[0]])
        ln = c['ln']
        lt = min(max(c['lt'], -c['mu_s'] * ln), c['mu_s'] * ln)
        apply(c, ln * n + lt * t)
        acc.append([ln, lt])
    # the sweep order: the part-part contacts' two halves alternating, then the others;
    # sweeps alternate forward and backward
    pairs = sum(1 for c in contacts if c['b'] >= 0)
    half = (pairs + 1) // 2
    order = [i for k in range(half) for i in (k, half + k) if i < pairs]
    order += list(range(pairs, len(contacts)))

    def sweeps(visits, limit_passes, step, tolerance):
        for it in range(limit_passes):
            residual = 0.0
            for k in (visits if it % 2 == 0 else visits[::-1]):
                residual = max(residual, step(k))
            if residual <= tolerance:
                break

    def impulse_sweeps(visits, limit_passes, step, tolerance):
        # full sweeps, each followed, while parts move, by partial sweeps over their contacts;
        # every visit counts against the budget of limit_passes full sweeps
        full_sweeps, it, moving, used = 0, 0, None, 0
        while True:
            order_now = visits if it % 2 == 0 else visits[::-1]
            if moving is not None:
                order_now = [k for k in order_now if {contacts[k]['a'], contacts[k]['b']}
                             & moving]
                stats['partial_visits'] += len(order_now)
            residual, moved = 0.0, set()
            used += len(order_now)
            for k in order_now:
                change = step(k)
                residual = max(residual, change)
                if change > MOVING_SHARE * tolerance:
                    moved |= {contacts[k]['a'], contacts[k]['b']} - {-1}
            it += 1
            if moving is None:
                full_sweeps += 1
                if residual <= tolerance:
                    break
                partial = 0
            else:
                partial += 1
            if used >= limit_passes * len(visits):
                break
            moving = moved if moved and partial < PARTIAL_SWEEPS else None
        stats['full_sweeps'] = full_sweeps
        stats['sweeps'] = it
        stats['visits'] = used

    def solve(k, touching=False):
        c = contacts[k]
        n = np.asarray(c['n'], dtype=float)
        t = np.array([-n[1], n[0]])
        un = relative(c) @ n
        ln, lt = acc[k]
        target = 0.0 if touching else min(c['depth'], 0.0) / h
        ln1 = max(ln + (target - un) / inverse_mass(c, n), 0.0)
        apply(c, (ln1 - ln) * n)
        ut = relative(c) @ t
        limit = friction_ref(c['mu_s'], c['mu_k'], c['v_t'], abs(ut)) * ln1
        lt1 = min(max(lt - ut / inverse_mass(c, t), -limit), limit)
        apply(c, (lt1 - lt) * t)
        acc[k] = [ln1, lt1]
        return (abs(ln1 - ln) + abs(lt1 - lt)) * inverse_mass(c, n)

    def bounce_step(k):
        c = contacts[k]
        n = np.asarray(c['n'], dtype=float)
        t = np.array([-n[1], n[0]])
        ln, lt = acc[k]
        ln1 = max(ln + (bounce[k] - relative(c) @ n) / inverse_mass(c, n), 0.0)
        apply(c, (ln1 - ln) * n)
        limit = friction_ref(c['mu_s'], c['mu_k'], c['v_t'], abs(relative(c) @ t)) * ln1
        lt1 = min(max(lt, -limit), limit)
        apply(c, (lt1 - lt) * t)
        acc[k] = [ln1, lt1]
        return (abs(ln1 - ln) + abs(lt1 - lt)) * inverse_mass(c, n)

    limit = passes
    if work > 0 and contacts:
        limit = max(passes, min(max_passes, work // len(contacts)))
    impulse_sweeps(order, limit, solve, tolerance)
    kept = [list(a) for a in acc]      # the next substep's warm start: before the bounce
    # impacts (no warm start) of free islands (none of their loaded contacts warm started or on
    # a moving body): Poisson's restitution on their compression swept to convergence as
    # touching contacts, and no warm start from them; in held islands an impact struck within
    # the substep gets e times its impact impulse, the bouncing contacts are driven to their
    # bounce speed
    loaded = [c for k, c in enumerate(contacts) if acc[k][0] > 0.0]
    group = {i: {i} for c in loaded for i in (c['a'], c['b']) if i >= 0}
    for c in loaded:
        if c['b'] >= 0 and group[c['a']] is not group[c['b']]:
            group[c['a']] |= group[c['b']]
            for i in group[c['b']]:
                group[i] = group[c['a']]
    held = [group[c['a']] for c in loaded if c['ln'] != 0.0
            or (c['b'] < 0 and (np.any(np.asarray(c['bv']) != 0.0) or c['bw'] != 0.0))]

    def impact(k):
        c = contacts[k]
        p = acc[k][0] - min(c['depth'], 0.0) / h / inverse_mass(c, c['n'])
        return (acc[k][0] > 0.0 and c['ln'] == 0.0 and c['e'] > 0.0
                and (bounce[k] > 0.0 or p * inverse_mass(c, c['n']) > 0.02)), p

    impacts = []
    for k in order:
        if impact(k)[0] and any(group[contacts[k]['a']] is g for g in held):
            if bounce[k] == 0.0:
                c = contacts[k]
                apply(c, c['e'] * impact(k)[1] * np.asarray(c['n'], dtype=float))
                acc[k][0] += c['e'] * impact(k)[1]
        elif impact(k)[0]:
            impacts.append(k)
    bouncing = [k for k in order if bounce[k] > 0.0 and acc[k][0] > 0.0 and k not in impacts]
    if impacts:
        sweeps(impacts, bounce_passes, lambda k: solve(k, True), bounce_tolerance)
        for k in impacts:
            c = contacts[k]
            apply(c, c['e'] * acc[k][0] * np.asarray(c['n'], dtype=float))
            acc[k][0] *= 1.0 + c['e']
            kept[k] = [0.0, 0.0]
    if bouncing:
        sweeps(bouncing, bounce_passes, bounce_step, bounce_tolerance)
    # no rise of the kinetic energy of any island (parts joined by contacts) beyond the heat of
    # the surface friction and the work of moving kinematic bodies
    island = list(range(len(v)))

    def root(i):
        while island[i] != i:
            i = island[i]
        return i

    for c in contacts:
        if c['b'] >= 0:
            ra, rb = root(c['a']), root(c['b'])
            island[max(ra, rb)] = min(ra, rb)
    roots = np.array([root(i) for i in range(len(v))])
    m, inertia = 1.0 / m_inv, 1.0 / i_inv
    dv, dw = v - v0, w - w0
    factor = np.ones(len(v))
    for r in set(roots.tolist()):
        k = roots == r
        g = float(np.sum(m[k, None] * v0[k] * dv[k]) + np.sum(inertia[k] * w0[k] * dw[k]))
        q = 0.5 * float(np.sum(m[k, None] * dv[k] ** 2) + np.sum(inertia[k] * dw[k] ** 2))
        work = 0.0 if heat is None else float(np.sum(heat[k]))
        for (ln, lt), c in zip(acc, contacts):
            if c['b'] < 0 and roots[c['a']] == r:
                n = np.asarray(c['n'], dtype=float)
                rb = c['rb']
                u = np.asarray(c['bv'], dtype=float) + c['bw'] * np.array([-rb[1], rb[0]])
                work += (ln * n + lt * np.array([-n[1], n[0]])) @ u
        if g + q > work and q > 0.0:
            factor[k] = max((work - g) / q, 0.0)
    v[:] = v0 + factor[:, None] * dv
    w[:] = w0 + factor * dw
    return [(factor[c['a']] * ln, factor[c['a']] * lt) for (ln, lt), c in zip(kept, contacts)]


def box_core(x: float, y: float, yaw: float, length: float, width: float) -> np.ndarray:
    """Return the counter-clockwise corners of a box [m]."""
    c, s = math.cos(yaw), math.sin(yaw)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * [length / 2, width / 2]
    return local @ np.array([[c, s], [-s, c]]) + [x, y]
