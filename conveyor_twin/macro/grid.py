"""Macro grid geometry: rasterisation of belts, obstacles and actuators, and the velocity field.

A macro zone is covered by ``ny x nx`` square cells of edge ``h`` [m]; cell ``(iy, ix)`` has its
centre at ``(origin_x + (ix + 0.5) h, origin_y + (iy + 0.5) h)``. Velocities live on the cell
faces (a staggered, MAC-like layout), which makes every flux a single number per face and mass
conservation exact up to round-off:

- ``ux[iy, ix]`` (``ny x (nx + 1)``): x velocity [m/s] on the face between cells ``ix - 1`` and
  ``ix`` (``ix = 0`` and ``ix = nx`` are the left and right domain edges);
- ``uy[iy, ix]`` (``(ny + 1) x nx``): y velocity [m/s] on the face between rows ``iy - 1`` and
  ``iy``.

Construction of the field (Hoher et al.; Göttlich et al. 2014):

1. Cell-centre belt velocity: the speed of the belt whose rectangle holds the centre times its
   direction (later belts in the cell win where belts overlap; no belt: at rest). A curved
   belt's cells take its rigid rotation, an engaged transfer unit's cells its own velocity
   (:mod:`conveyor_twin.macro.curves`).
2. Solid cells: every cell whose square is reached by an obstacle (wall/deflector capsule chains,
   pegs, convex polygons) or an engaged actuator. The test is a conservative square-shape
   distance, so a thin diagonal deflector always rasterises to an 8-connected staircase and never
   leaks under the 4-connected face fluxes.
3. Sliding: fluid cells that touch a solid cell (8-neighbourhood) carry the outward unit normal of
   the obstacle's exact geometry and the obstacle's own normal speed ``w`` (0 for fixed
   obstacles). Where the belt pushes into the obstacle (``v . n < w``) the normal component is
   replaced by ``w``: ``v <- v + (w - v . n) n``. Material slides along deflectors and queues in
   front of walls; a moving pusher face carries what it meets at its own speed.
4. Faces: the mean of the two neighbouring cell-centre components; zero if either cell is solid.
   Domain-edge faces take the edge cell's component. Faces of a curved belt take the clamped
   stream function's flux instead (exact and divergence-free, arcs as streamlines), except
   where a neighbouring cell is solid, slides, or is on another belt.
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

from numba import njit
import numpy as np

from conveyor_twin.cell.model import Actuator, Belt, Cell, Obstacle, Rect, Zone
from conveyor_twin.macro import curves as _curves

# Fluid cells within this many cells (Chebyshev) of an actuator's solid cells get its sliding
# constraint; for fixed obstacles the band is a parameter of rasterise_static.
SLIDE_BAND_CELLS = 1
# Cell velocities below this [m/s] are zero.
VELOCITY_EPS = 1e-12


@dataclass(frozen=True)
class Grid:
    """A uniform macro grid.

    :param origin_x: x of the lower-left grid corner [m].
    :param origin_y: y of the lower-left grid corner [m].
    :param h: cell edge (resolution) [m].
    :param nx: cells along x. :param ny: cells along y.
    """

    origin_x: float
    origin_y: float
    h: float
    nx: int
    ny: int

    @classmethod
    def from_zone(cls, zone: Zone) -> 'Grid':
        """Cover ``zone.region`` with cells of ``zone.resolution`` (rounded to whole cells)."""
        x0, y0, x1, y1 = zone.region
        h = zone.resolution
        nx = max(1, int(round((x1 - x0) / h)))
        ny = max(1, int(round((y1 - y0) / h)))
        return cls(float(x0), float(y0), float(h), nx, ny)

    def centres(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return cell-centre coordinate arrays ``(xc, yc)``, each ``(ny, nx)`` [m]."""
        xs = self.origin_x + (np.arange(self.nx) + 0.5) * self.h
        ys = self.origin_y + (np.arange(self.ny) + 0.5) * self.h
        return np.meshgrid(xs, ys)

    @property
    def n_boundary(self) -> int:
        """Number of boundary faces: left (ny), right (ny), bottom (nx), top (nx)."""
        return 2 * (self.nx + self.ny)

    def boundary_faces(self) -> Tuple[np.ndarray, np.ndarray]:
        """Return the centres [m] and outward unit normals of the boundary faces, ``(nb, 2)`` each.

        Order: left faces by ``iy``, right faces by ``iy``, bottom faces by ``ix``, top faces
        by ``ix`` (the order of every per-boundary-face array of :class:`MacroSim`).
        """
        g = self
        ys = g.origin_y + (np.arange(g.ny) + 0.5) * g.h
        xs = g.origin_x + (np.arange(g.nx) + 0.5) * g.h
        x_end, y_end = g.origin_x + g.nx * g.h, g.origin_y + g.ny * g.h
        centres = np.concatenate([
            np.stack([np.full(g.ny, g.origin_x), ys], 1),
            np.stack([np.full(g.ny, x_end), ys], 1),
            np.stack([xs, np.full(g.nx, g.origin_y)], 1),
            np.stack([xs, np.full(g.nx, y_end)], 1)])
        normals = np.concatenate([
            np.tile([-1.0, 0.0], (g.ny, 1)), np.tile([1.0, 0.0], (g.ny, 1)),
            np.tile([0.0, -1.0], (g.nx, 1)), np.tile([0.0, 1.0], (g.nx, 1))])
        return centres, normals

    def cell_slices(self, rect: Rect) -> Tuple[slice, slice]:
        """Return ``(rows, cols)`` slices of the cells whose centres lie in ``rect`` [m]."""
        x0, y0, x1, y1 = rect
        h = self.h
        ix0 = max(0, int(math.ceil((x0 - self.origin_x) / h - 0.5)))
        ix1 = min(self.nx, int(math.floor((x1 - self.origin_x) / h - 0.5)) + 1)
        iy0 = max(0, int(math.ceil((y0 - self.origin_y) / h - 0.5)))
        iy1 = min(self.ny, int(math.floor((y1 - self.origin_y) / h - 0.5)) + 1)
        return slice(iy0, max(iy0, iy1)), slice(ix0, max(ix0, ix1))


# --- shape distances (vectorised over cell centres) -------------------------------------------

def _segment_closest(px: np.ndarray, py: np.ndarray, a: Sequence[float],
                     b: Sequence[float]) -> Tuple[np.ndarray, np.ndarray]:
    """Return the closest points on segment ``a-b`` to the points ``(px, py)``."""
    ax, ay = a
    dx, dy = b[0] - ax, b[1] - ay
    ll = dx * dx + dy * dy
    if ll == 0.0:
        return np.full_like(px, ax), np.full_like(py, ay)
    t = np.clip(((px - ax) * dx + (py - ay) * dy) / ll, 0.0, 1.0)
    return ax + t * dx, ay + t * dy


def _point_shape(px: np.ndarray, py: np.ndarray, qx: np.ndarray, qy: np.ndarray,
                 radius: float, h: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the square-shape distance, and the unit normal, from core points ``q`` of radius.

    The square-shape distance is ``|c - q| - radius - s(u)`` with ``s(u) = h/2 (|ux| + |uy|)``
    the support of the cell square in the direction ``u`` of ``c - q``: it is <= 0 when the
    disc of ``radius`` about ``q`` reaches into the square of the cell at ``c`` (exact for the
    nearest point of a straight edge, conservative near ends).
    """
    ex, ey = px - qx, py - qy
    dist = np.hypot(ex, ey)
    safe = np.where(dist > 0.0, dist, 1.0)
    ux, uy = np.where(dist > 0.0, ex / safe, 0.0), np.where(dist > 0.0, ey / safe, 0.0)
    support = 0.5 * h * (np.abs(ux) + np.abs(uy))
    support = np.where(dist > 0.0, support, 0.5 * h * math.sqrt(2.0))
    return dist - radius - support, ux, uy


def _polyline_shape(px, py, points, radius, h):
    best = np.full(px.shape, np.inf)
    nx_, ny_ = np.zeros(px.shape), np.zeros(px.shape)
    pairs = list(zip(points[:-1], points[1:])) or [(points[0], points[0])]
    for a, b in pairs:
        qx, qy = _segment_closest(px, py, a, b)
        d, ux, uy = _point_shape(px, py, qx, qy, radius, h)
        closer = d < best
        best = np.where(closer, d, best)
        nx_, ny_ = np.where(closer, ux, nx_), np.where(closer, uy, ny_)
    return best, nx_, ny_


def _convex_polygon_shape(px, py, points, h):
    """Square-shape distance to a convex polygon (CCW) with separating axes; outward normal."""
    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    # Separation along each edge normal, including the square's support.
    sep = np.full(px.shape, -np.inf)
    for k in range(n):
        a, b = pts[k], pts[(k + 1) % n]
        ex, ey = b[0] - a[0], b[1] - a[1]
        length = math.hypot(ex, ey)
        if length == 0.0:
            continue
        nxk, nyk = ey / length, -ex / length   # outward for CCW
        s = (px - a[0]) * nxk + (py - a[1]) * nyk - 0.5 * h * (abs(nxk) + abs(nyk))
        sep = np.maximum(sep, s)
    # Separation along the square's axes.
    xmin, ymin = pts.min(axis=0)
    xmax, ymax = pts.max(axis=0)
    sx = np.maximum(xmin - px, px - xmax) - 0.5 * h
    sy = np.maximum(ymin - py, py - ymax) - 0.5 * h
    sep = np.maximum(sep, np.maximum(sx, sy))
    # Normal: from the closest boundary point outward.
    closed = list(pts) + [pts[0]]
    dbest = np.full(px.shape, np.inf)
    nx_, ny_ = np.zeros(px.shape), np.zeros(px.shape)
    for a, b in zip(closed[:-1], closed[1:]):
        qx, qy = _segment_closest(px, py, a, b)
        d = np.hypot(px - qx, py - qy)
        closer = d < dbest
        safe = np.where(d > 0.0, d, 1.0)
        nx_ = np.where(closer, (px - qx) / safe, nx_)
        ny_ = np.where(closer, (py - qy) / safe, ny_)
        dbest = np.where(closer, d, dbest)
    return sep, nx_, ny_


def obstacle_shape(obstacle: Obstacle, px: np.ndarray, py: np.ndarray,
                   h: float) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(d, nx, ny)``: square-shape distance [m] (<= 0: the cell is solid) and normal."""
    if obstacle.kind in ('wall', 'deflector'):
        return _polyline_shape(px, py, obstacle.points, 0.5 * obstacle.thickness, h)
    if obstacle.kind == 'peg':
        cx, cy = obstacle.points[0]
        return _point_shape(px, py, np.full_like(px, cx), np.full_like(py, cy),
                            obstacle.radius, h)
    return _convex_polygon_shape(px, py, obstacle.points, h)


def actuator_polygon(actuator: Actuator, position: float) -> np.ndarray:
    """Return the footprint of ``actuator`` at ``position`` as a CCW rectangle ``(4, 2)`` [m]."""
    ax, ay = actuator.axis
    if actuator.kind == 'diverter':
        c, s = math.cos(position), math.sin(position)
        ax, ay = c * ax - s * ay, s * ax + c * ay
        bx, by = actuator.base
        cx, cy = bx + 0.5 * actuator.length * ax, by + 0.5 * actuator.length * ay
    elif actuator.kind == 'pusher':
        cx, cy = actuator.base[0] + position * ax, actuator.base[1] + position * ay
    else:
        cx, cy = actuator.base
    px, py = -ay, ax
    hl, hw = 0.5 * actuator.length, 0.5 * actuator.width
    corners = [(-hl, -hw), (hl, -hw), (hl, hw), (-hl, hw)]
    return np.array([(cx + u * ax + v * px, cy + u * ay + v * py) for u, v in corners])


def actuator_engaged(actuator: Actuator, position: float) -> bool:
    """Return True if ``actuator`` acts at ``position``: a stopper (a solid region) or a
    transfer unit (a carrying surface) only if lifted to ``engage_height``."""
    if actuator.kind in ('stopper', 'transfer'):
        return position >= actuator.engage_height
    return True


def actuator_wall_velocity(actuator: Actuator, position: float, rate: float, px: np.ndarray,
                           py: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return the velocity [m/s] of the actuator's material points at ``(px, py)``.

    :param rate: d position / dt [m/s or rad/s].
    """
    if actuator.kind == 'pusher':
        return (np.full(px.shape, rate * actuator.axis[0]),
                np.full(px.shape, rate * actuator.axis[1]))
    if actuator.kind == 'diverter':
        bx, by = actuator.base
        return -rate * (py - by), rate * (px - bx)
    return np.zeros(px.shape), np.zeros(px.shape)


def belt_index_of_cells(grid: Grid, belts: Sequence[Belt]) -> np.ndarray:
    """Return ``(ny, nx)`` int32: index of the belt under each cell centre, -1 for none.

    A curved belt also takes the cells no belt holds whose square reaches into its annulus
    (:func:`conveyor_twin.macro.curves.add_rim_cells`).
    """
    xc, yc = grid.centres()
    out = np.full((grid.ny, grid.nx), -1, dtype=np.int32)
    for k, belt in enumerate(belts):
        if belt.curve is not None:
            out[_curves.sector_mask(belt.curve, xc, yc)] = k
            continue
        dx, dy = belt.direction
        rx, ry = xc - belt.start[0], yc - belt.start[1]
        along = rx * dx + ry * dy
        across = -rx * dy + ry * dx
        inside = (along >= 0.0) & (along <= belt.length) & (np.abs(across) <= 0.5 * belt.width)
        out[inside] = k
    _curves.add_rim_cells(out, belts, xc, yc, grid.h)
    return out


def _band(solid: np.ndarray, cells: int) -> np.ndarray:
    """Return cells within ``cells`` (Chebyshev) of a True cell of ``solid``, minus ``solid``."""
    ny, nx = solid.shape
    grown = solid.copy()
    for _ in range(cells):
        g = grown.copy()
        g[1:, :] |= grown[:-1, :]
        g[:-1, :] |= grown[1:, :]
        g[:, 1:] |= grown[:, :-1]
        g[:, :-1] |= grown[:, 1:]
        g[1:, 1:] |= grown[:-1, :-1]
        g[:-1, :-1] |= grown[1:, 1:]
        g[1:, :-1] |= grown[:-1, 1:]
        g[:-1, 1:] |= grown[1:, :-1]
        grown = g
    return grown & ~solid


def rasterise_static(grid: Grid, obstacles: Sequence[Obstacle], band_cells: int = 1):
    """Rasterise fixed obstacles.

    :param band_cells: width of the sliding band in cells (Chebyshev distance to the solid).

    :return: ``(solid, normal)``: ``(ny, nx)`` uint8 solid mask and ``(ny, nx, 2)`` float64
        outward normals on the sliding band (zero elsewhere).
    """
    xc, yc = grid.centres()
    solid = np.zeros((grid.ny, grid.nx), dtype=bool)
    shapes = []
    tol = 1e-9 * grid.h
    for obstacle in obstacles:
        d, nx_, ny_ = obstacle_shape(obstacle, xc, yc, grid.h)
        mask = d < -tol
        solid |= mask
        shapes.append((mask, d, nx_, ny_))
    normal = np.zeros((grid.ny, grid.nx, 2))
    best = np.full((grid.ny, grid.nx), np.inf)
    for mask, d, nx_, ny_ in shapes:
        if not mask.any():
            continue
        band = _band(mask, band_cells) & ~solid
        take = band & (d < best)
        normal[take, 0] = nx_[take]
        normal[take, 1] = ny_[take]
        best = np.where(take, d, best)
    return solid.astype(np.uint8), normal


def rasterise_actuators(grid: Grid, actuators: Sequence[Actuator], positions: np.ndarray,
                        rates: np.ndarray, static_solid: np.ndarray):
    """Rasterise the engaged actuators at ``positions`` moving at ``rates``.

    :return: ``(solid, normal, wall_speed, wall_velocity)``: uint8 mask ``(ny, nx)``, outward
        normals ``(ny, nx, 2)`` and the wall's normal speed [m/s] ``(ny, nx)`` on the sliding
        band, and the wall velocity [m/s] ``(ny, nx, 2)`` on the solid cells (for sweeping).
    """
    xc, yc = grid.centres()
    ny, nx = grid.ny, grid.nx
    solid = np.zeros((ny, nx), dtype=bool)
    normal = np.zeros((ny, nx, 2))
    wall_speed = np.zeros((ny, nx))
    wall_velocity = np.zeros((ny, nx, 2))
    best = np.full((ny, nx), np.inf)
    tol = 1e-9 * grid.h
    for actuator, position, rate in zip(actuators, positions, rates):
        if actuator.kind == 'transfer' or not actuator_engaged(actuator, float(position)):
            continue  # a transfer unit is a surface, not a solid (see MacroSim)
        poly = actuator_polygon(actuator, float(position))
        d, nx_, ny_ = _convex_polygon_shape(xc, yc, poly, grid.h)
        mask = d < -tol
        if not mask.any():
            continue
        solid |= mask
        vx, vy = actuator_wall_velocity(actuator, float(position), float(rate), xc, yc)
        wall_velocity[mask, 0] = vx[mask]
        wall_velocity[mask, 1] = vy[mask]
        band = _band(mask, SLIDE_BAND_CELLS) & ~mask & (static_solid == 0)
        take = band & (d < best)
        normal[take, 0] = nx_[take]
        normal[take, 1] = ny_[take]
        wall_speed[take] = vx[take] * nx_[take] + vy[take] * ny_[take]
        best = np.where(take, d, best)
    solid &= static_solid == 0
    return solid.astype(np.uint8), normal, wall_speed, wall_velocity


@njit(cache=True, inline='always')
def _psi_cell(belt_idx: np.ndarray, solid: np.ndarray, normal_s: np.ndarray,
              normal_a: np.ndarray, iy: int, ix: int, owner: int) -> int:
    """Classify cell ``(iy, ix)`` for a face of curved belt ``owner``: 0 blocks its stream
    function (solid, or on another belt), 1 passes it (outside the grid, or fluid on that
    belt without a sliding constraint), 2 slides (on that belt, with a sliding constraint),
    3 is fluid on no belt (the arcs bound the belt: a face to it always takes psi)."""
    ny, nx = belt_idx.shape
    if iy < 0 or ix < 0 or iy >= ny or ix >= nx:
        return 1
    k = belt_idx[iy, ix]
    if solid[iy, ix] != 0 or (k != owner and k >= 0):
        return 0
    if k < 0:
        return 3
    if (normal_s[iy, ix, 0] != 0.0 or normal_s[iy, ix, 1] != 0.0
            or normal_a[iy, ix, 0] != 0.0 or normal_a[iy, ix, 1] != 0.0):
        return 2
    return 1


@njit(cache=True, inline='always')
def _psi_face(ca: int, cb: int) -> bool:
    """True if a face between cells of classes ``ca``, ``cb`` (:func:`_psi_cell`) takes psi."""
    if ca == 0 or cb == 0:
        return False
    return (ca != 2 and cb != 2) or ca == 3 or cb == 3


@njit(cache=True)
def build_velocity(belt_idx: np.ndarray, belt_dir: np.ndarray, speeds: np.ndarray,
                   solid: np.ndarray, normal_s: np.ndarray, normal_a: np.ndarray,
                   wall_a: np.ndarray, vc: np.ndarray, ux: np.ndarray,
                   uy: np.ndarray, curve: tuple) -> float:
    """Fill the cell and face velocities in place; return the largest cell outflow speed.

    :param belt_idx: ``(ny, nx)`` int32 belt index per cell, -1 for none.
    :param belt_dir: ``(nb, 2)`` unit running directions. :param speeds: ``(nb,)`` [m/s].
    :param curve: ``(curved, own_x, own_y, unit_x, unit_y, unit_c)`` of
        :func:`conveyor_twin.macro.curves.unit_fields`: a curved belt's cells take
        ``speed * unit_c`` (then the sliding constraints as for straight belts), and a face
        it owns takes ``speed * unit_x`` / ``unit_y`` if both its cells are fluid and on that
        belt or on none, and neither has a sliding constraint unless the other is on no belt
        (a curve's arcs always bound it); every other face is built as below. Straight belts
        do not use it.
    :param solid: ``(ny, nx)`` uint8, 1 for solid (static or actuator).
    :param normal_s: ``(ny, nx, 2)`` fixed-obstacle sliding normals (zero: none).
    :param normal_a: ``(ny, nx, 2)`` actuator sliding normals. :param wall_a: their normal
        wall speeds [m/s].
    :param vc: out ``(ny, nx, 2)`` cell-centre velocity [m/s].
    :param ux: out ``(ny, nx + 1)``. :param uy: out ``(ny + 1, nx)`` face velocities [m/s].
    :return: ``max over cells of (max(ux_right, 0) + max(-ux_left, 0))`` and the same in y,
        whichever is larger [m/s]: the CFL speed of a split sweep.
    """
    curved, own_x, own_y, unit_x, unit_y, unit_c = curve
    ny, nx = belt_idx.shape
    for iy in range(ny):
        for ix in range(nx):
            vx = 0.0
            vy = 0.0
            k = belt_idx[iy, ix]
            if k >= 0 and solid[iy, ix] == 0:
                if curved[k] != 0:
                    vx = speeds[k] * unit_c[iy, ix, 0]
                    vy = speeds[k] * unit_c[iy, ix, 1]
                else:
                    vx = speeds[k] * belt_dir[k, 0]
                    vy = speeds[k] * belt_dir[k, 1]
                for which in range(2):
                    if which == 0:
                        nnx = normal_s[iy, ix, 0]
                        nny = normal_s[iy, ix, 1]
                        w = 0.0
                    else:
                        nnx = normal_a[iy, ix, 0]
                        nny = normal_a[iy, ix, 1]
                        w = wall_a[iy, ix]
                    if nnx != 0.0 or nny != 0.0:
                        vn = vx * nnx + vy * nny
                        if vn < w:
                            vx += (w - vn) * nnx
                            vy += (w - vn) * nny
            elif solid[iy, ix] == 0 and (normal_a[iy, ix, 0] != 0.0
                                         or normal_a[iy, ix, 1] != 0.0):
                # Off the belt but swept by a moving actuator face.
                w = wall_a[iy, ix]
                if w > 0.0:
                    vx = w * normal_a[iy, ix, 0]
                    vy = w * normal_a[iy, ix, 1]
            # Round-off of the projection (1e-16 m/s) must not open a boundary face.
            vc[iy, ix, 0] = vx if abs(vx) > VELOCITY_EPS else 0.0
            vc[iy, ix, 1] = vy if abs(vy) > VELOCITY_EPS else 0.0
    for iy in range(ny):
        for ix in range(nx + 1):
            if ix == 0:
                v = vc[iy, 0, 0] if solid[iy, 0] == 0 else 0.0
            elif ix == nx:
                v = vc[iy, nx - 1, 0] if solid[iy, nx - 1] == 0 else 0.0
            elif solid[iy, ix - 1] != 0 or solid[iy, ix] != 0:
                v = 0.0
            else:
                v = 0.5 * (vc[iy, ix - 1, 0] + vc[iy, ix, 0])
            o = own_x[iy, ix]
            if o >= 0 and _psi_face(_psi_cell(belt_idx, solid, normal_s, normal_a, iy, ix - 1, o),
                                    _psi_cell(belt_idx, solid, normal_s, normal_a, iy, ix, o)):
                v = speeds[o] * unit_x[iy, ix]
                v = v if abs(v) > VELOCITY_EPS else 0.0
            ux[iy, ix] = v
    for iy in range(ny + 1):
        for ix in range(nx):
            if iy == 0:
                v = vc[0, ix, 1] if solid[0, ix] == 0 else 0.0
            elif iy == ny:
                v = vc[ny - 1, ix, 1] if solid[ny - 1, ix] == 0 else 0.0
            elif solid[iy - 1, ix] != 0 or solid[iy, ix] != 0:
                v = 0.0
            else:
                v = 0.5 * (vc[iy - 1, ix, 1] + vc[iy, ix, 1])
            o = own_y[iy, ix]
            if o >= 0 and _psi_face(_psi_cell(belt_idx, solid, normal_s, normal_a, iy - 1, ix, o),
                                    _psi_cell(belt_idx, solid, normal_s, normal_a, iy, ix, o)):
                v = speeds[o] * unit_y[iy, ix]
                v = v if abs(v) > VELOCITY_EPS else 0.0
            uy[iy, ix] = v
    smax = 0.0
    for iy in range(ny):
        for ix in range(nx):
            sx = max(ux[iy, ix + 1], 0.0) + max(-ux[iy, ix], 0.0)
            sy = max(uy[iy + 1, ix], 0.0) + max(-uy[iy, ix], 0.0)
            smax = max(smax, sx, sy)
    return smax


def zone_for(cell: Cell, zone: Optional[object]) -> Zone:
    """Return the zone named or given by ``zone`` (None: the first zone of the cell)."""
    if zone is None:
        return cell.zones[0]
    if isinstance(zone, Zone):
        return zone
    for z in cell.zones:
        if z.name == zone:
            return z
    names: List[str] = [z.name for z in cell.zones]
    msg = f'unknown zone {zone!r}; the cell has {names}'
    raise KeyError(msg)
