"""The Göttlich et al. (2014) collision operator on the staggered grid (numba kernels).

``I(rho) = -eps H(rho - rho_max) grad(eta * rho) / sqrt(1 + |grad(eta * rho)|^2)`` is a
velocity [m/s] added to the belt velocity on every face.

Discretisation:

- Mollifier ``eta``: the separable product of two 1D kernels
  ``w_k = (1 - (k h / delta)^2)^3`` for ``|k| h < delta`` (delta = ``mollifier_width``, default two
  cells: taps 0.42, 1, 0.42), applied as a *normalised* convolution over fluid cells only,
  ``phi = eta * (m rho) / eta * m`` with ``m`` the fluid mask. Solid cells and the outside of the
  grid are therefore neither empty nor full: they are ignored (a Neumann-like wall), so a wall
  does not attract or repel material by itself. ``eta * m`` is precomputed when solids change.
- Gradient on a face: the normal component is the two-cell difference of ``phi``; the tangential
  component the mean of the two cells' central differences.
- ``H`` on a face: 1 if either neighbouring cell has ``rho >= rho_max`` (the face between a full
  and a free cell must push the full one out), 0 otherwise. Faces touching a solid cell and the
  domain edges get no operator velocity.
- Cost control: the operator is evaluated only inside the bounding box of cells with
  ``rho >= rho_max`` grown by the stencil, and skipped when there is none.

In SI units ``|grad phi|`` is about ``rho_max / h`` (1e6 /m^3 for 10 mm spacers on a 1 cm grid),
so the normalisation makes ``I`` a push of speed ``eps`` down the density gradient wherever the
density is at its maximum; ``eps`` must exceed the belt speed for the operator to hold the
density at ``rho_max`` against a wall (see :mod:`conveyor_twin.macro.solver`).
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


@njit(cache=True)
def mask_convolution(solid: np.ndarray, w: np.ndarray, tmp: np.ndarray,
                     den: np.ndarray) -> None:
    """Fill ``den = eta * m`` (``m`` = 1 on fluid cells) over the whole grid."""
    ny, nx = solid.shape
    r = (w.size - 1) // 2
    for j in range(ny):
        for i in range(nx):
            s = 0.0
            for k in range(-r, r + 1):
                ii = i + k
                if 0 <= ii < nx and solid[j, ii] == 0:
                    s += w[k + r]
            tmp[j, i] = s
    for j in range(ny):
        for i in range(nx):
            s = 0.0
            for k in range(-r, r + 1):
                jj = j + k
                if 0 <= jj < ny:
                    s += w[k + r] * tmp[jj, i]
            den[j, i] = s


@njit(cache=True)
def full_box(rho: np.ndarray, solid: np.ndarray, rho_max: float, box: np.ndarray) -> bool:
    """Store the bounding box ``[iy0, iy1, ix0, ix1)`` of cells with ``rho >= rho_max``.

    :return: True if there is any such cell.
    """
    ny, nx = rho.shape
    iy0, iy1, ix0, ix1 = ny, -1, nx, -1
    for j in range(ny):
        for i in range(nx):
            if rho[j, i] >= rho_max:
                if j < iy0:
                    iy0 = j
                iy1 = j
                if i < ix0:
                    ix0 = i
                if i > ix1:
                    ix1 = i
    if iy1 < 0:
        box[0] = 0
        box[1] = 0
        box[2] = 0
        box[3] = 0
        return False
    box[0] = iy0
    box[1] = iy1 + 1
    box[2] = ix0
    box[3] = ix1 + 1
    return True


@njit(cache=True)
def restore_box(wx: np.ndarray, wy: np.ndarray, ux: np.ndarray, uy: np.ndarray,
                box: np.ndarray) -> None:
    """Reset the total face velocities of the face box ``box`` to the belt field."""
    iy0, iy1, ix0, ix1 = box[0], box[1], box[2], box[3]
    for j in range(iy0, iy1):
        for f in range(ix0, ix1 + 1):
            wx[j, f] = ux[j, f]
    for f in range(iy0, iy1 + 1):
        for i in range(ix0, ix1):
            wy[f, i] = uy[f, i]


@njit(cache=True)
def collision_operator(rho: np.ndarray, solid: np.ndarray, rho_max: float, eps: float,
                       h: float, w: np.ndarray, dx: np.ndarray, dy: np.ndarray,
                       gx: np.ndarray, gy: np.ndarray, ux: np.ndarray, uy: np.ndarray,
                       wx: np.ndarray, wy: np.ndarray, box: np.ndarray,
                       face_box: np.ndarray) -> bool:
    """Set the total face velocities ``wx = ux + Ix``, ``wy = uy + Iy`` [m/s] from ``rho``.

    ``grad(eta * rho)`` is computed as ``eta * grad(rho)``: the face differences of ``rho``
    (zero across faces touching a solid cell: no gradient through a wall) mollified with the
    separable taps ``w`` along both axes. Only the faces of the grown box of full cells are
    touched; the box written by the previous call (``face_box``) is first reset to the belt
    field ``ux``, ``uy``.

    :param w: 1D mollifier taps. :param dx: work ``(ny, nx + 1)``, :param dy: work
        ``(ny + 1, nx)``: face differences [parts/m^3]; :param gx: work ``(ny, nx + 1)``,
        :param gy: work ``(ny + 1, nx)``: mollified gradients (x pass, then both).
    :param box: work int64 ``(4,)``. :param face_box: int64 ``(4,)``, see above.
    :return: True if the operator is active anywhere.
    """
    ny, nx = rho.shape
    restore_box(wx, wy, ux, uy, face_box)
    full = rho_max * (1.0 - H_TOLERANCE)
    if not full_box(rho, solid, full, box):
        face_box[0] = 0
        face_box[1] = 0
        face_box[2] = 0
        face_box[3] = 0
        return False
    r = (w.size - 1) // 2
    inv_h = 1.0 / h
    # Operator faces: around the cells of the full box grown by one.
    fy0, fy1 = max(0, box[0] - 1), min(ny, box[1] + 1)
    fx0, fx1 = max(0, box[2] - 1), min(nx, box[3] + 1)
    # Work region: r + 2 cells further, so the mollified gradients used are exact.
    r0, r1 = max(0, box[0] - r - 3), min(ny, box[1] + r + 3)
    c0, c1 = max(0, box[2] - r - 3), min(nx, box[3] + r + 3)
    # Raw face differences (zero across solid faces and the domain edge).
    for j in range(r0, r1):
        for f in range(c0, c1 + 1):
            d = 0.0
            if 0 < f < nx and solid[j, f - 1] == 0 and solid[j, f] == 0:
                d = (rho[j, f] - rho[j, f - 1]) * inv_h
            dx[j, f] = d
    for f in range(r0, r1 + 1):
        for i in range(c0, c1):
            d = 0.0
            if 0 < f < ny and solid[f - 1, i] == 0 and solid[f, i] == 0:
                d = (rho[f, i] - rho[f - 1, i]) * inv_h
            dy[f, i] = d
    # Separable mollification: along x into gx / gy, then along y back into dx / dy.
    for j in range(r0, r1):
        for f in range(c0, c1 + 1):
            s = 0.0
            for k in range(-r, r + 1):
                ff = f + k
                if c0 <= ff <= c1:
                    s += w[k + r] * dx[j, ff]
            gx[j, f] = s
    for f in range(r0, r1 + 1):
        for i in range(c0, c1):
            s = 0.0
            for k in range(-r, r + 1):
                ii = i + k
                if c0 <= ii < c1:
                    s += w[k + r] * dy[f, ii]
            gy[f, i] = s
    for j in range(r0, r1):
        for f in range(c0, c1 + 1):
            s = 0.0
            for k in range(-r, r + 1):
                jj = j + k
                if r0 <= jj < r1:
                    s += w[k + r] * gx[jj, f]
            dx[j, f] = s
    for f in range(r0, r1 + 1):
        for i in range(c0, c1):
            s = 0.0
            for k in range(-r, r + 1):
                ff = f + k
                if r0 <= ff <= r1:
                    s += w[k + r] * gy[ff, i]
            dy[f, i] = s
    # Operator on the faces of the box: dx, dy now hold the mollified gradients.
    for j in range(fy0, fy1):
        for f in range(max(fx0, 1), min(fx1, nx - 1) + 1):
            if solid[j, f - 1] != 0 or solid[j, f] != 0:
                continue
            if rho[j, f - 1] < full and rho[j, f] < full:
                continue
            tx = dx[j, f]
            if tx * (rho[j, f] - rho[j, f - 1]) <= 0.0:
                continue  # push only down the local density difference (monotone)
            ty = 0.25 * (dy[j, f - 1] + dy[j, f] + dy[j + 1, f - 1] + dy[j + 1, f])
            wx[j, f] = ux[j, f] - eps * tx / math.sqrt(1.0 + tx * tx + ty * ty)
    for f in range(max(fy0, 1), min(fy1, ny - 1) + 1):
        for i in range(fx0, fx1):
            if solid[f - 1, i] != 0 or solid[f, i] != 0:
                continue
            if rho[f - 1, i] < full and rho[f, i] < full:
                continue
            ty = dy[f, i]
            if ty * (rho[f, i] - rho[f - 1, i]) <= 0.0:
                continue
            tx = 0.25 * (dx[f - 1, i] + dx[f - 1, i + 1] + dx[f, i] + dx[f, i + 1])
            wy[f, i] = uy[f, i] - eps * ty / math.sqrt(1.0 + tx * tx + ty * ty)
    face_box[0] = fy0
    face_box[1] = fy1
    face_box[2] = fx0
    face_box[3] = fx1
    return True
