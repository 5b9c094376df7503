"""Near phase: contacts between rounded convex shapes (numba kernels).

Every shape is a *rounded convex polygon*: a core of ``nv`` world-frame vertices (counter-
clockwise) swept by a radius ``r``. A disc is one vertex with its radius, a wall segment a
capsule (two vertices, half its thickness), a peg one vertex, a box or polygon ``nv >= 3``
vertices with radius 0. Edge ``i`` runs from vertex ``i`` to ``i + 1`` and its outward normal is
``(e_y, -e_x) / |e|``; a two-vertex core thus has the two opposite normals of the segment.

Contacts are written to ``out`` (float64, length 8):
``[n_x, n_y, p0_x, p0_y, depth0, p1_x, p1_y, depth1]`` with the unit normal pointing from B to
A, contact points [m] midway between the two surfaces and depths [m] (> 0: overlapping). The
functions return the number of contacts (0, 1 or 2). The polygon-polygon case follows Box2D
v3's ``b2CollidePolygons`` (SAT on the cores, reference/incident edge clipping, vertex-vertex
regions of rounded cores by segment distance).
"""

import math

from numba import njit

# Below this core separation [m] the polygon cores count as overlapping (clip, no vertex case).
CORE_SLOP = 1e-9


@njit(cache=True)
def _edge_normal(v, i, nv):
    j = i + 1 if i + 1 < nv else 0
    ex = v[j, 0] - v[i, 0]
    ey = v[j, 1] - v[i, 1]
    length = math.sqrt(ex * ex + ey * ey)
    if length == 0.0:
        return 1.0, 0.0
    return ey / length, -ex / length


@njit(cache=True)
def circle_circle(ax, ay, ra, bx, by, rb, out):
    """Contact of two circles; return the number of contacts (0 or 1).

    :param ax: centre of A [m]. :param ra: radius of A [m]; same for B.
    """
    dx = ax - bx
    dy = ay - by
    rsum = ra + rb
    d2 = dx * dx + dy * dy
    if d2 >= rsum * rsum:
        return 0
    d = math.sqrt(d2)
    if d > 0.0:
        nx = dx / d
        ny = dy / d
    else:
        nx = 1.0
        ny = 0.0
    out[0] = nx
    out[1] = ny
    # midway between the surfaces: B's surface point + half the overlap
    depth = rsum - d
    out[2] = bx + nx * (rb - 0.5 * depth)
    out[3] = by + ny * (rb - 0.5 * depth)
    out[4] = depth
    return 1


@njit(cache=True)
def circle_segment(px, py, ra, v, rb, out):
    """Contact of a circle (centre p, radius ra) with the capsule ``v[0]``-``v[1]`` (radius rb)."""
    ex = v[1, 0] - v[0, 0]
    ey = v[1, 1] - v[0, 1]
    l2 = ex * ex + ey * ey
    t = 0.0
    if l2 > 0.0:
        t = ((px - v[0, 0]) * ex + (py - v[0, 1]) * ey) / l2
        t = min(max(t, 0.0), 1.0)
    qx = v[0, 0] + t * ex
    qy = v[0, 1] + t * ey
    dx = px - qx
    dy = py - qy
    rsum = ra + rb
    d2 = dx * dx + dy * dy
    if d2 >= rsum * rsum:
        return 0
    d = math.sqrt(d2)
    if d > 0.0:
        nx = dx / d
        ny = dy / d
    elif l2 > 0.0:
        le = math.sqrt(l2)
        nx = ey / le
        ny = -ex / le
    else:
        nx = 1.0
        ny = 0.0
    depth = rsum - d
    out[0] = nx
    out[1] = ny
    out[2] = qx + nx * (rb - 0.5 * depth)
    out[3] = qy + ny * (rb - 0.5 * depth)
    out[4] = depth
    return 1


@njit(cache=True)
def circle_polygon(px, py, ra, v, nv, rb, out):
    """Contact of a circle with a rounded convex polygon of ``nv >= 3`` core vertices."""
    best = -1e300
    edge = 0
    for i in range(nv):
        nx, ny = _edge_normal(v, i, nv)
        s = nx * (px - v[i, 0]) + ny * (py - v[i, 1])
        if s > best:
            best = s
            edge = i
    rsum = ra + rb
    if best >= rsum:
        return 0
    j = edge + 1 if edge + 1 < nv else 0
    v1x = v[edge, 0]
    v1y = v[edge, 1]
    v2x = v[j, 0]
    v2y = v[j, 1]
    u1 = (px - v1x) * (v2x - v1x) + (py - v1y) * (v2y - v1y)
    u2 = (px - v2x) * (v1x - v2x) + (py - v2y) * (v1y - v2y)
    if u1 < 0.0 and best > CORE_SLOP:
        qx, qy = v1x, v1y
    elif u2 < 0.0 and best > CORE_SLOP:
        qx, qy = v2x, v2y
    else:
        nx, ny = _edge_normal(v, edge, nv)
        depth = rsum - best
        out[0] = nx
        out[1] = ny
        # the core face point below the centre, pushed out by rb
        fx = px - best * nx
        fy = py - best * ny
        out[2] = fx + nx * (rb - 0.5 * depth)
        out[3] = fy + ny * (rb - 0.5 * depth)
        out[4] = depth
        return 1
    dx = px - qx
    dy = py - qy
    d2 = dx * dx + dy * dy
    if d2 >= rsum * rsum:
        return 0
    d = math.sqrt(d2)
    nx = dx / d
    ny = dy / d
    depth = rsum - d
    out[0] = nx
    out[1] = ny
    out[2] = qx + nx * (rb - 0.5 * depth)
    out[3] = qy + ny * (rb - 0.5 * depth)
    out[4] = depth
    return 1


@njit(cache=True)
def point_shape(px, py, ra, v, nv, rb, out):
    """Contact of a circle (centre p, radius ra) with any rounded shape (``nv`` >= 1)."""
    if nv == 1:
        return circle_circle(px, py, ra, v[0, 0], v[0, 1], rb, out)
    if nv == 2:
        return circle_segment(px, py, ra, v, rb, out)
    return circle_polygon(px, py, ra, v, nv, rb, out)


@njit(cache=True)
def _max_separation(v1, n1, v2, n2):
    """Return (edge of poly 1, its largest separation from poly 2's vertices) [m]."""
    best = -1e300
    edge = 0
    for i in range(n1):
        nx, ny = _edge_normal(v1, i, n1)
        si = 1e300
        for j in range(n2):
            s = nx * (v2[j, 0] - v1[i, 0]) + ny * (v2[j, 1] - v1[i, 1])
            if s < si:
                si = s
        if si > best:
            best = si
            edge = i
    return edge, best


@njit(cache=True)
def segment_distance(p1x, p1y, q1x, q1y, p2x, p2y, q2x, q2y):
    """Closest points of segments p1-q1 and p2-q2: return (fraction 1, fraction 2), in [0, 1]."""
    d1x = q1x - p1x
    d1y = q1y - p1y
    d2x = q2x - p2x
    d2y = q2y - p2y
    rx = p1x - p2x
    ry = p1y - p2y
    dd1 = d1x * d1x + d1y * d1y
    dd2 = d2x * d2x + d2y * d2y
    rd1 = rx * d1x + ry * d1y
    rd2 = rx * d2x + ry * d2y
    eps = 1e-30
    if dd1 < eps and dd2 < eps:
        return 0.0, 0.0
    if dd1 < eps:
        return 0.0, min(max(rd2 / dd2, 0.0), 1.0)
    if dd2 < eps:
        return min(max(-rd1 / dd1, 0.0), 1.0), 0.0
    d12 = d1x * d2x + d1y * d2y
    den = dd1 * dd2 - d12 * d12
    f1 = 0.0
    if den != 0.0:
        f1 = min(max((d12 * rd2 - rd1 * dd2) / den, 0.0), 1.0)
    f2 = (d12 * f1 + rd2) / dd2
    if f2 < 0.0:
        f2 = 0.0
        f1 = min(max(-rd1 / dd1, 0.0), 1.0)
    elif f2 > 1.0:
        f2 = 1.0
        f1 = min(max((d12 - rd1) / dd1, 0.0), 1.0)
    return f1, f2


@njit(cache=True)
def _clip(v1, n1, r1, v2, n2, r2, i11, i21, flip, out):
    """Clip poly 2's incident edge ``i21`` against poly 1's reference edge ``i11``."""
    i12 = i11 + 1 if i11 + 1 < n1 else 0
    i22 = i21 + 1 if i21 + 1 < n2 else 0
    nx, ny = _edge_normal(v1, i11, n1)
    tx = -ny
    ty = nx
    v11x, v11y = v1[i11, 0], v1[i11, 1]
    v12x, v12y = v1[i12, 0], v1[i12, 1]
    v21x, v21y = v2[i21, 0], v2[i21, 1]
    v22x, v22y = v2[i22, 0], v2[i22, 1]
    lower1 = 0.0
    upper1 = (v12x - v11x) * tx + (v12y - v11y) * ty
    upper2 = (v21x - v11x) * tx + (v21y - v11y) * ty
    lower2 = (v22x - v11x) * tx + (v22y - v11y) * ty
    span = upper2 - lower2
    if lower2 < lower1 and span > 1e-15:
        f = (lower1 - lower2) / span
        lox = v22x + f * (v21x - v22x)
        loy = v22y + f * (v21y - v22y)
    else:
        lox, loy = v22x, v22y
    if upper2 > upper1 and span > 1e-15:
        f = (upper1 - lower2) / span
        upx = v22x + f * (v21x - v22x)
        upy = v22y + f * (v21y - v22y)
    else:
        upx, upy = v21x, v21y
    sep_lo = (lox - v11x) * nx + (loy - v11y) * ny
    sep_up = (upx - v11x) * nx + (upy - v11y) * ny
    # midway between the rounded surfaces
    lox += 0.5 * (r1 - r2 - sep_lo) * nx
    loy += 0.5 * (r1 - r2 - sep_lo) * ny
    upx += 0.5 * (r1 - r2 - sep_up) * nx
    upy += 0.5 * (r1 - r2 - sep_up) * ny
    rsum = r1 + r2
    # reference normal points from poly 1 to poly 2; the output normal points from B to A
    if flip:
        out[0] = nx
        out[1] = ny
    else:
        out[0] = -nx
        out[1] = -ny
    count = 0
    d_lo = rsum - sep_lo
    d_up = rsum - sep_up
    if d_lo > 0.0:
        out[2] = lox
        out[3] = loy
        out[4] = d_lo
        count = 1
    if d_up > 0.0:
        k = 2 + 3 * count
        out[k] = upx
        out[k + 1] = upy
        out[k + 2] = d_up
        count += 1
    return count


@njit(cache=True)
def polygon_polygon(va, na, ra, vb, nb, rb, out):
    """Contact of two rounded convex polygons with ``na, nb >= 2`` core vertices (0..2 points)."""
    edge_a, sep_a = _max_separation(va, na, vb, nb)
    edge_b, sep_b = _max_separation(vb, nb, va, na)
    rsum = ra + rb
    if sep_a >= rsum or sep_b >= rsum:
        return 0
    flip = sep_b > 0.1 * CORE_SLOP + sep_a
    if flip:
        # B is the reference polygon: incident edge of A most anti-parallel to B's normal
        snx, sny = _edge_normal(vb, edge_b, nb)
        best = 1e300
        edge_a = 0
        for i in range(na):
            nx, ny = _edge_normal(va, i, na)
            d = snx * nx + sny * ny
            if d < best:
                best = d
                edge_a = i
        v1, n1, r1, i11, v2, n2, r2, i21 = vb, nb, rb, edge_b, va, na, ra, edge_a
        sep = sep_b
    else:
        snx, sny = _edge_normal(va, edge_a, na)
        best = 1e300
        edge_b = 0
        for i in range(nb):
            nx, ny = _edge_normal(vb, i, nb)
            d = snx * nx + sny * ny
            if d < best:
                best = d
                edge_b = i
        v1, n1, r1, i11, v2, n2, r2, i21 = va, na, ra, edge_a, vb, nb, rb, edge_b
        sep = sep_a
    if sep > CORE_SLOP:
        # cores apart: vertex-vertex region (rounded shapes) or edge region
        i12 = i11 + 1 if i11 + 1 < n1 else 0
        i22 = i21 + 1 if i21 + 1 < n2 else 0
        f1, f2 = segment_distance(v1[i11, 0], v1[i11, 1], v1[i12, 0], v1[i12, 1],
                                  v2[i21, 0], v2[i21, 1], v2[i22, 0], v2[i22, 1])
        end1 = f1 == 0.0 or f1 == 1.0
        end2 = f2 == 0.0 or f2 == 1.0
        if end1 and end2:
            k1 = i11 if f1 == 0.0 else i12
            k2 = i21 if f2 == 0.0 else i22
            dx = v2[k2, 0] - v1[k1, 0]
            dy = v2[k2, 1] - v1[k1, 1]
            d = math.sqrt(dx * dx + dy * dy)
            if d >= rsum or d == 0.0:
                return 0
            nx = dx / d
            ny = dy / d
            depth = rsum - d
            c1x = v1[k1, 0] + r1 * nx
            c1y = v1[k1, 1] + r1 * ny
            c2x = v2[k2, 0] - r2 * nx
            c2y = v2[k2, 1] - r2 * ny
            # (nx, ny) points from poly 1 to poly 2
            if flip:
                out[0] = nx
                out[1] = ny
            else:
                out[0] = -nx
                out[1] = -ny
            out[2] = 0.5 * (c1x + c2x)
            out[3] = 0.5 * (c1y + c2y)
            out[4] = depth
            return 1
    return _clip(v1, n1, r1, v2, n2, r2, i11, i21, flip, out)


@njit(cache=True)
def collide(va, na, ra, vb, nb, rb, out):
    """Contact of two rounded convex shapes A and B; normal in ``out`` points from B to A.

    :param va: core vertices of A, world frame, shape (>= na, 2) [m].
    :param na: number of core vertices of A (1 circle, 2 capsule, >= 3 polygon).
    :param ra: radius of A [m]. Same for B.
    :param out: float64[8] output, see the module docstring.
    :return: number of contact points.
    """
    if na == 1:
        return point_shape(va[0, 0], va[0, 1], ra, vb, nb, rb, out)
    if nb == 1:
        count = point_shape(vb[0, 0], vb[0, 1], rb, va, na, ra, out)
        if count:
            # p lies midway; only the normal flips
            out[0] = -out[0]
            out[1] = -out[1]
        return count
    return polygon_polygon(va, na, ra, vb, nb, rb, out)


@njit(cache=True)
def box_vertices(x, y, yaw, hl, hw, out):
    """Write the 4 counter-clockwise world corners of a box into ``out`` (4, 2).

    :param x: centre [m]. :param yaw: heading of the body x axis [rad].
    :param hl: half length along body x [m]. :param hw: half width [m].
    """
    c = math.cos(yaw)
    s = math.sin(yaw)
    ax = c * hl
    ay = s * hl
    bx = -s * hw
    by = c * hw
    out[0, 0] = x - ax - bx
    out[0, 1] = y - ay - by
    out[1, 0] = x + ax - bx
    out[1, 1] = y + ay - by
    out[2, 0] = x + ax + bx
    out[2, 1] = y + ay + by
    out[3, 0] = x - ax + bx
    out[3, 1] = y - ay + by
