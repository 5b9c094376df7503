"""The Göttlich et al. (2014) collision operator on the staggered grid (numba kernels).

``I(rho) = -eps H(rho - rho_max) grad(eta * rho) / sqrt(1 + |grad(eta * rho)|^2)`` is a
velocity [m/s] added to the belt velocity on every face.

Discretisation:

- Mollifier ``eta``: the separable product of two 1D kernels
  ``w_k = (1 - (k h / delta)^2)^3`` for ``|k| h < delta`` (delta = ``mollifier_width``, default
  two cells: taps 0.23, 0.54, 0.23), applied to the gradient: ``grad(eta * rho)`` is computed as
  ``eta * grad(rho)`` from the face differences of ``rho``, which are zero across faces touching
  a solid cell and outside the grid. A wall therefore has no density of its own (no spurious
  push into or away from it); in the open both forms are the same.
- Gradient on a face: the normal component is the mollified face difference; the tangential
  component the mean of the four mollified differences around the face.
- ``H`` on a face: 1 if either neighbouring cell has ``rho >= rho_max (1 - H_TOLERANCE)`` (the
  face between a full and a free cell must push the full one out), 0 otherwise. Faces touching
  a solid cell and the domain edges get no operator velocity.
- Monotonicity: a face pushes only down its own density difference (the sign of the mollified
  gradient must agree with ``rho_R - rho_L``; otherwise the face gets no operator velocity).
  Without this, the mollified gradient of a pattern of period about ``2 delta`` has the wrong
  sign, and since ``|grad phi|`` is huge in SI units the normalised operator pushes at full speed
  ``eps`` *into* density peaks (observed: 25-60 rho_max spikes with a 5-cell mollifier).
- Cost control: the operator is evaluated only, row by row, around the cells with
  ``rho >= rho_max`` (grown by the stencil), and skipped when there is none.

In SI units ``|grad phi|`` is about ``rho_max / h`` (1e6 /m^3 for 10 mm spacers on a 1 cm grid),
so the normalisation makes ``I`` a push of speed ``eps`` down the density gradient wherever the
density is at its maximum. Alone, this holds the density near ``rho_max`` only approximately (up
to about 1.9 rho_max in a stopper queue: the push switches on only above rho_max, in whatever
direction the local gradient happens to point); :class:`MacroSim` therefore also applies the
capped variant's receiver-capacity cut to the total flux by default (``guard=True``).
"""

import math

from numba import njit
import numpy as np

# H(rho - rho_max) is 1 from rho >= rho_max (1 - H_TOLERANCE): with the capacity guard the
# density reaches rho_max only up to round-off.
H_TOLERANCE = 1e-9


def mollifier_weights(h: float, width: float) -> np.ndarray:
    """Return the 1D mollifier taps ``w_{-R..R}`` for cell edge ``h`` and support ``width`` [m].

    ``width <= 0`` means two cells.
    """
    delta = width if width > 0.0 else 2.0 * h
    radius = max(0, int(math.ceil(delta / h)) - 1)
    k = np.arange(-radius, radius + 1, dtype=np.float64)
    w = (1.0 - (k * h / delta) ** 2) ** 3
    w[w < 0.0] = 0.0
    return w / w.sum()


@njit(cache=True, inline='always')
def _face_row_range(rng: np.ndarray, f: int, ny: int):
    """Return the column range ``[a, b)`` of y-face row ``f``: union of its two cell rows."""
    a = rng[min(f, ny - 1), 0]
    b = rng[min(f, ny - 1), 1]
    if f > 0:
        a2 = rng[f - 1, 0]
        b2 = rng[f - 1, 1]
        if b2 > a2:
            if b > a:
                a = min(a, a2)
                b = max(b, b2)
            else:
                a = a2
                b = b2
    return a, b


@njit(cache=True)
def restore_faces(wx: np.ndarray, wy: np.ndarray, ux: np.ndarray, uy: np.ndarray,
                  lohi: np.ndarray) -> None:
    """Reset to the belt field the faces :func:`collision_operator` sets for ``lohi``."""
    ny = ux.shape[0]
    nx = ux.shape[1] - 1
    for j in range(ny):
        lo = lohi[j, 0]
        hi = lohi[j, 1]
        if hi <= lo:
            continue
        for f in range(max(lo, 1), min(hi, nx - 1) + 1):
            wx[j, f] = ux[j, f]
    for f in range(1, ny):
        a, b = _face_row_range(lohi, f, ny)
        for i in range(a, b):
            wy[f, i] = uy[f, i]


@njit(cache=True)
def full_rows(rho: np.ndarray, full: float, lohi: np.ndarray) -> bool:
    """Store per row the column range ``[lo, hi)`` of cells with ``rho >= full``.

    ``(0, 0)`` for a row without such a cell. One branch-free min/max pass per row (it
    vectorises).

    :return: True if there is any such cell.
    """
    ny, nx = rho.shape
    found = False
    for j in range(ny):
        row = rho[j]
        lo = nx
        hi = 0
        for i in range(nx):
            is_full = row[i] >= full
            lo = min(lo, i if is_full else nx)
            hi = max(hi, i + 1 if is_full else 0)
        if hi > lo:
            found = True
            lohi[j, 0] = lo
            lohi[j, 1] = hi
        else:
            lohi[j, 0] = 0
            lohi[j, 1] = 0
    return found


@njit(cache=True, error_model='numpy')
def collision_operator(field: tuple, rho_max: float, h: float, collision: tuple) -> bool:
    """Set the total face velocities ``wx = ux + Ix``, ``wy = uy + Iy`` [m/s] from ``rho``.

    The arrays come in the groups of :func:`conveyor_twin.macro.solver.advance` (unpacked
    here, no copies): ``field = (rho, ux, uy, wx, wy, solid)``: density [parts/m^2], belt and
    total face velocities [m/s], solid mask; ``collision = (use_op, eps, w, dx, dy, gx, gy,
    lohi, rng)``: strength ``eps`` [m/s] and the arrays below (``use_op`` is not read here).
    ``rho_max`` [parts/m^2], cell edge ``h`` [m].

    ``grad(eta * rho)`` is computed as ``eta * grad(rho)``: the face differences of ``rho``
    (zero across faces touching a solid cell: no gradient through a wall) mollified with the
    separable taps ``w`` along both axes. Work is confined, row by row, to the full cells grown
    by ``K = r + 1`` cells (Chebyshev), enough for every value the operator faces use to be
    computed from fresh inputs; the faces set by the previous call (those of ``lohi``) are
    first reset to the belt field ``ux``, ``uy``.

    :param w: 1D mollifier taps. :param dx: work ``(ny, nx + 1)``, :param dy: work
        ``(ny + 1, nx)``: face differences [parts/m^3]; :param gx: work ``(ny, nx + 1)``,
        :param gy: work ``(ny + 1, nx)``: mollified gradients (x pass, then both).
    :param lohi: int64 ``(ny, 2)``: per-row range of full cells, kept between calls (see
        above; all ``(0, 0)`` or stale ranges where ``wx``, ``wy`` equal ``ux``, ``uy`` when
        the field is rebuilt).
    :param rng: work int64 ``(ny, 2)``: per-row work range.
    :return: True if the operator is active anywhere.
    """
    rho, ux, uy, wx, wy, solid = field
    _use_op, eps, w, dx, dy, gx, gy, lohi, rng = collision
    ny, nx = rho.shape
    restore_faces(wx, wy, ux, uy, lohi)
    full = rho_max * (1.0 - H_TOLERANCE)
    if not full_rows(rho, full, lohi):
        for j in range(ny):
            rng[j, 0] = 0
            rng[j, 1] = 0
        return False
    r = (w.size - 1) // 2
    # An operator face reads mollified gradients at most one cell off the full cells' ranges
    # (the four tangential neighbours); each is a sum of r taps along y of sums of r taps
    # along x. With the work range of every row covering the full cells of the rows within
    # r + 1, grown by r + 1, every value an operator face reads is a complete sum of fresh
    # differences (the ranges of the rows the y taps reach cover it with r columns to spare).
    grow = r + 1
    for j in range(ny):
        a = nx
        b = 0
        for jj in range(max(0, j - grow), min(ny, j + grow + 1)):
            if lohi[jj, 1] > lohi[jj, 0]:
                a = min(a, lohi[jj, 0] - grow)
                b = max(b, lohi[jj, 1] + grow)
        if b > a:
            rng[j, 0] = max(a, 0)
            rng[j, 1] = min(b, nx)
        else:
            rng[j, 0] = 0
            rng[j, 1] = 0
    inv_h = 1.0 / h
    # Raw face differences (zero across solid faces and the domain edge).
    for j in range(ny):
        a = rng[j, 0]
        b = rng[j, 1]
        if b <= a:
            continue
        if a == 0:
            dx[j, 0] = 0.0
        if b == nx:
            dx[j, nx] = 0.0
        for f in range(max(a, 1), min(b, nx - 1) + 1):
            ok = (solid[j, f - 1] == 0) & (solid[j, f] == 0)
            d = (rho[j, f] - rho[j, f - 1]) * inv_h
            dx[j, f] = d if ok else 0.0
    for f in range(ny + 1):
        a, b = _face_row_range(rng, f, ny)
        if f == 0 or f == ny:
            for i in range(a, b):
                dy[f, i] = 0.0
            continue
        for i in range(a, b):
            ok = (solid[f - 1, i] == 0) & (solid[f, i] == 0)
            d = (rho[f, i] - rho[f - 1, i]) * inv_h
            dy[f, i] = d if ok else 0.0
    # Separable mollification: along x into gx / gy, then along y back into dx / dy. Each
    # output is the sum over the taps in tap order, skipping taps outside the region (the
    # grid); the loops run tap by tap over contiguous memory, which gives the same sums.
    for j in range(ny):
        a = rng[j, 0]
        b = rng[j, 1]
        if b <= a:
            continue
        for f in range(a, b + 1):
            gx[j, f] = 0.0
        for k in range(-r, r + 1):
            wk = w[k + r]
            for f in range(max(a, a - k), min(b, b - k) + 1):
                gx[j, f] += wk * dx[j, f + k]
    for f in range(ny + 1):
        a, b = _face_row_range(rng, f, ny)
        for i in range(a, b):
            gy[f, i] = 0.0
        for k in range(-r, r + 1):
            wk = w[k + r]
            for i in range(max(a, a - k), min(b, b - k)):
                gy[f, i] += wk * dy[f, i + k]
    # The y pass only where the operator faces read its result: x faces of the full cells'
    # ranges of rows j - 1 .. j + 1 (tangential neighbours of the y faces), and y faces one
    # column beyond the ranges of their two rows.
    for j in range(ny):
        a = nx
        b = -1
        for jj in range(max(0, j - 1), min(ny, j + 2)):
            if lohi[jj, 1] > lohi[jj, 0]:
                a = min(a, lohi[jj, 0])
                b = max(b, lohi[jj, 1])
        a = max(a, rng[j, 0])
        b = min(b, rng[j, 1])
        if b < a:
            continue
        for f in range(a, b + 1):
            dx[j, f] = 0.0
        for k in range(-r, r + 1):
            jj = j + k
            if 0 <= jj < ny:
                wk = w[k + r]
                for f in range(a, b + 1):
                    dx[j, f] += wk * gx[jj, f]
    for f in range(ny + 1):
        a, b = _face_row_range(lohi, f, ny)
        if b <= a:
            continue
        ra, rb = _face_row_range(rng, f, ny)
        a = max(a - 1, ra)
        b = min(b + 1, rb)
        for i in range(a, b):
            dy[f, i] = 0.0
        for k in range(-r, r + 1):
            ff = f + k
            if 0 <= ff <= ny:
                wk = w[k + r]
                for i in range(a, b):
                    dy[f, i] += wk * gy[ff, i]
    # Operator on the faces next to full cells: dx, dy now hold the mollified gradients.
    # Branch-free (every face of the range is computed, inactive ones get the belt velocity,
    # which they hold already), so the loops vectorise.
    for j in range(ny):
        lo = lohi[j, 0]
        hi = lohi[j, 1]
        if hi <= lo:
            continue
        for f in range(max(lo, 1), min(hi, nx - 1) + 1):
            rl = rho[j, f - 1]
            rr = rho[j, f]
            tx = dx[j, f]
            ty = 0.25 * (dy[j, f - 1] + dy[j, f] + dy[j + 1, f - 1] + dy[j + 1, f])
            # push only down the local density difference (monotone)
            act = ((solid[j, f - 1] == 0) & (solid[j, f] == 0) & ((rl >= full) | (rr >= full))
                   & (tx * (rr - rl) > 0.0))
            u = ux[j, f]
            v = u - eps * tx / math.sqrt(1.0 + tx * tx + ty * ty)
            wx[j, f] = v if act else u
    for f in range(1, ny):
        a, b = _face_row_range(lohi, f, ny)
        for i in range(a, b):
            rl = rho[f - 1, i]
            rr = rho[f, i]
            ty = dy[f, i]
            tx = 0.25 * (dx[f - 1, i] + dx[f - 1, i + 1] + dx[f, i] + dx[f, i + 1])
            act = ((solid[f - 1, i] == 0) & (solid[f, i] == 0) & ((rl >= full) | (rr >= full))
                   & (ty * (rr - rl) > 0.0))
            u = uy[f, i]
            v = u - eps * ty / math.sqrt(1.0 + tx * tx + ty * ty)
            wy[f, i] = v if act else u
    return True
