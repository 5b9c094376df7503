"""Curved belts and transfer units on the macro grid: cell membership and unit-speed fields.

A curved belt's surface moves as the rigid rotation ``v = omega x (x - c)`` about its centre
``c`` with ``omega = direction * speed / centre_radius`` [rad/s]. On the staggered grid its
face velocities come from the stream function of the rotation clamped to the belt's radii,

    ``psi(x) = -(omega / 2) clamp(|x - c|, r_in, r_out)^2``  [m^2/s],

as the mean normal velocity over a face: ``ux = (psi(top) - psi(bottom)) / h`` on an x face,
``uy = -(psi(right) - psi(left)) / h`` on a y face (the face's two end points). So:

- inside the annulus a face carries exactly the rotation at its centre (``psi`` is quadratic);
- a face across an arc carries exactly the part of the rotation's flux inside the belt, and the
  arcs are streamlines (``psi`` is constant beyond them): nothing leaks off the sides of a curve
  through the staircase of cells that rasterises an arc;
- the field is discretely divergence-free (the face differences of ``psi`` sum to zero around
  every cell), so a uniform density stays uniform to round-off and the scheme stays conservative.

Membership: a cell belongs to a curved belt if its centre lies on the belt (later belts win, as
for straight belts), or if no belt holds its centre but its square reaches radially into the
annulus with its centre within the sweep (the rim cells that hold the arc's partial flux).

All values here are for a belt speed of 1 m/s; :func:`conveyor_twin.macro.grid.build_velocity`
scales them by the current speed. Straight belts have no entries (their field is unchanged).
"""

import math
from typing import Sequence, Tuple

import numpy as np

from conveyor_twin.cell.curves import BeltCurve
from conveyor_twin.cell.model import Actuator, Belt

# Angular slack [rad] of the sweep test (a centre exactly on an end ray belongs to the curve).
ANGLE_SLACK = 1e-12


def _travelled(curve: BeltCurve, xc: np.ndarray, yc: np.ndarray) -> np.ndarray:
    """Return the angle [rad] travelled from the start angle to each point, in [0, 2 pi)."""
    phi = np.arctan2(yc - curve.centre[1], xc - curve.centre[0])
    return np.mod(curve.direction * (phi - curve.start_angle), 2.0 * math.pi)


def _in_sweep(curve: BeltCurve, xc: np.ndarray, yc: np.ndarray) -> np.ndarray:
    sweep = abs(curve.sweep)
    t = _travelled(curve, xc, yc)
    return (t <= sweep + ANGLE_SLACK) | (t >= 2.0 * math.pi - ANGLE_SLACK)


def sector_mask(curve: BeltCurve, xc: np.ndarray, yc: np.ndarray) -> np.ndarray:
    """Return True where the points ``(xc, yc)`` [m] lie on the annular sector (edges in)."""
    r = np.hypot(xc - curve.centre[0], yc - curve.centre[1])
    return (r >= curve.inner_radius) & (r <= curve.outer_radius) & _in_sweep(curve, xc, yc)


def rim_mask(curve: BeltCurve, xc: np.ndarray, yc: np.ndarray, h: float) -> np.ndarray:
    """Return True for cells (centres ``xc``, ``yc``, edge ``h`` [m]) whose square reaches
    radially into the annulus (open interval) and whose centre lies within the sweep."""
    dx, dy = xc - curve.centre[0], yc - curve.centre[1]
    near_x = np.maximum(np.abs(dx) - 0.5 * h, 0.0)
    near_y = np.maximum(np.abs(dy) - 0.5 * h, 0.0)
    r_min = np.hypot(near_x, near_y)
    r_max = np.hypot(np.abs(dx) + 0.5 * h, np.abs(dy) + 0.5 * h)
    return (r_max > curve.inner_radius) & (r_min < curve.outer_radius) & _in_sweep(curve, xc, yc)


def add_rim_cells(idx: np.ndarray, belts: Sequence[Belt], xc: np.ndarray, yc: np.ndarray,
                  h: float) -> None:
    """Give the cells that no belt holds but a curve's rim reaches to that curve (in place)."""
    for k, belt in enumerate(belts):
        if belt.curve is None:
            continue
        rim = rim_mask(belt.curve, xc, yc, h) & (idx < 0)
        idx[rim] = k


def _psi(curve: BeltCurve, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Clamped stream function [m^2/s] of the curve at unit centre-line speed."""
    omega = curve.direction / curve.centre_radius
    r = np.clip(np.hypot(x - curve.centre[0], y - curve.centre[1]),
                curve.inner_radius, curve.outer_radius)
    return -0.5 * omega * r * r


def unit_fields(origin: Tuple[float, float], h: float, idx: np.ndarray,
                belts: Sequence[Belt]):
    """Return the unit-speed fields of the curved belts on the grid.

    :param origin: lower-left grid corner [m]. :param h: cell edge [m].
    :param idx: ``(ny, nx)`` int32 belt index per cell (rim cells included).
    :return: ``(curved, own_x, own_y, unit_x, unit_y, unit_c)``: uint8 ``(nb,)`` 1 for a
        curved belt; int32 face owners ``(ny, nx + 1)`` and ``(ny + 1, nx)``: the curved belt
        whose ``psi`` gives the face (its cells on one or both sides, no other belt's on the
        other; domain-edge faces: the edge cell's), -1 elsewhere; the faces' normal velocity
        [m/s] at 1 m/s, same shapes (0 where not owned); ``(ny, nx, 2)`` cell velocity at
        1 m/s of curved cells: the rotation at the centre, for a rim cell at the belt point
        nearest to it (radially): the surface velocity a part there has.
    """
    ny, nx = idx.shape
    ox, oy = origin
    curved = np.array([b.curve is not None for b in belts], dtype=np.uint8)
    own_x = np.full((ny, nx + 1), -1, dtype=np.int32)
    own_y = np.full((ny + 1, nx), -1, dtype=np.int32)
    unit_x = np.zeros((ny, nx + 1))
    unit_y = np.zeros((ny + 1, nx))
    unit_c = np.zeros((ny, nx, 2))
    if not curved.any():
        return curved, own_x, own_y, unit_x, unit_y, unit_c
    pad = np.full((ny + 2, nx + 2), -1, dtype=np.int32)
    pad[1:-1, 1:-1] = idx
    xs = ox + np.arange(nx + 1) * h       # face / corner x
    ys = oy + np.arange(ny + 1) * h       # face / corner y
    for k, belt in enumerate(belts):
        if belt.curve is None:
            continue
        mine = pad == k
        free = (pad == k) | (pad < 0)
        # x faces between pad columns ix and ix + 1 (cells ix - 1 and ix).
        left, right = mine[1:-1, :-1], mine[1:-1, 1:]
        ok_x = (left | right) & free[1:-1, :-1] & free[1:-1, 1:]
        bottom, top = mine[:-1, 1:-1], mine[1:, 1:-1]
        ok_y = (bottom | top) & free[:-1, 1:-1] & free[1:, 1:-1]
        gx, gy = np.meshgrid(xs, ys)                     # corners (ny + 1, nx + 1)
        psi = _psi(belt.curve, gx, gy)
        fx = (psi[1:, :] - psi[:-1, :]) / h              # (ny, nx + 1)
        fy = -(psi[:, 1:] - psi[:, :-1]) / h             # (ny + 1, nx)
        own_x[ok_x] = k
        own_y[ok_y] = k
        unit_x[ok_x] = fx[ok_x]
        unit_y[ok_y] = fy[ok_y]
        cells = idx == k
        c = belt.curve
        omega = c.direction / c.centre_radius
        xc = ox + (np.arange(nx) + 0.5) * h
        yc = oy + (np.arange(ny) + 0.5) * h
        dx, dy = np.meshgrid(xc - c.centre[0], yc - c.centre[1])
        r = np.hypot(dx, dy)
        scale = np.clip(r, c.inner_radius, c.outer_radius) / np.where(r > 0.0, r, 1.0)
        unit_c[cells, 0] = (-omega * dy * scale)[cells]
        unit_c[cells, 1] = (omega * dx * scale)[cells]
    return curved, own_x, own_y, unit_x, unit_y, unit_c


def transfer_masks(xc: np.ndarray, yc: np.ndarray,
                   actuators: Sequence[Actuator]) -> Tuple[Tuple[int, np.ndarray], ...]:
    """Return ``(actuator index, (ny, nx) bool footprint)`` of every transfer unit: the cells
    whose centres lie in its rectangle (``length`` along ``axis`` by ``width``, centred at
    ``base``; edges included)."""
    out = []
    for a, act in enumerate(actuators):
        if act.kind != 'transfer':
            continue
        ax, ay = act.axis
        norm = math.hypot(ax, ay)
        ax, ay = ax / norm, ay / norm
        rx, ry = xc - act.base[0], yc - act.base[1]
        along = rx * ax + ry * ay
        across = -rx * ay + ry * ax
        tol = 1e-12
        mask = ((np.abs(along) <= 0.5 * act.length + tol)
                & (np.abs(across) <= 0.5 * act.width + tol))
        out.append((a, mask))
    return tuple(out)


def transfer_engaged(actuator: Actuator, position: float) -> bool:
    """Return True if the transfer unit carries parts at lift ``position`` [m]."""
    return position >= actuator.engage_height


class Surfaces:
    """The moving surfaces of a macro grid: the belts, and the engaged transfer units.

    An engaged transfer unit is one more surface (index ``nb + t`` in :attr:`idx`) carrying the
    cells of its footprint at ``surface_speed`` along its axis (later units win where they
    overlap); it is not solid. Without transfer units :attr:`idx`, :attr:`direction` and
    :attr:`speeds` are the belts' own arrays, so a cell without them builds exactly the same
    field as before.

    :param grid: the macro grid (:class:`conveyor_twin.macro.grid.Grid`).
    :param cell: the validated cell. :param belt_idx: ``(ny, nx)`` belt index per cell.
    :param belt_dir: ``(nb, 2)`` running directions (zero for curved belts).
    :param speeds: ``(nb,)`` belt speeds [m/s] (the simulator's array).
    """

    def __init__(self, grid, cell, belt_idx: np.ndarray, belt_dir: np.ndarray,
                 speeds: np.ndarray) -> None:
        xc, yc = grid.centres()
        self.nb = len(cell.belts)
        self.actuators = tuple(cell.actuators)
        self.belt_idx = belt_idx
        self.curve = unit_fields((grid.origin_x, grid.origin_y), grid.h, belt_idx, cell.belts)
        self.transfers = transfer_masks(xc, yc, cell.actuators)
        self.engaged = tuple(False for _ in self.transfers)
        self.idx, self.direction, self.speeds = belt_idx, belt_dir, speeds
        if self.transfers:
            axes = np.array([self.actuators[a].axis for a, _ in self.transfers], dtype=float)
            axes /= np.hypot(axes[:, 0], axes[:, 1])[:, None]
            surface = [self.actuators[a].surface_speed for a, _ in self.transfers]
            self.direction = np.concatenate([belt_dir, axes])
            self.speeds = np.concatenate([speeds, np.array(surface, dtype=float)])
            curved = np.concatenate([self.curve[0], np.zeros(len(axes), dtype=np.uint8)])
            self.curve = (curved,) + self.curve[1:]
            self.idx = belt_idx.copy()

    def set_speeds(self, speeds: np.ndarray) -> None:
        """Copy the belt speeds [m/s] into the surface speeds (if they are separate arrays)."""
        if self.speeds is not speeds:
            self.speeds[:self.nb] = speeds

    def place(self, positions: np.ndarray) -> bool:
        """Update the transfer surfaces for the actuator ``positions``; True if any flipped."""
        if not self.transfers:
            return False
        engaged = tuple(transfer_engaged(self.actuators[a], float(positions[a]))
                        for a, _ in self.transfers)
        if engaged == self.engaged:
            return False
        self.engaged = engaged
        np.copyto(self.idx, self.belt_idx)
        for t, ((_, mask), on) in enumerate(zip(self.transfers, engaged)):
            if on:
                self.idx[mask] = self.nb + t
        return True


def split_rails(belts: Sequence[Belt], obstacles: Sequence):
    """Return ``(others, rails)``: the obstacles without the generated guide rails of curved
    belts (``<belt>_rail_inner`` / ``_outer``), and those rails. ``others`` is ``obstacles``
    itself when there are no rails.

    The macro grid does not rasterise guide rails as sliding walls: the arcs are already
    streamlines of the curve's field, and the staircase of a rail's solid cells would block
    faces the rotation crosses. A rail only makes solid the cells that no belt holds
    (:func:`rail_cells`), so nothing (the collision operator's push included) leaves the curve
    sideways.
    """
    names = {f'{b.name}_rail_{side}' for b in belts
             if b.curve is not None and b.curve.guide_rails for side in ('inner', 'outer')}
    if not names:
        return obstacles, ()
    others = tuple(o for o in obstacles if o.name not in names)
    rails = tuple(o for o in obstacles if o.name in names)
    return others, rails


def rail_cells(xc: np.ndarray, yc: np.ndarray, belts: Sequence[Belt],
               idx: np.ndarray) -> np.ndarray:
    """Return the ``(ny, nx)`` bool mask of the cells no belt holds that touch (8-neighbours)
    a cell of a curved belt with guide rails and whose centre lies within its sweep: the solid
    cells of its rails on the macro grid (what the rails' geometry reaches is added by the
    caller)."""
    out = np.zeros(idx.shape, dtype=bool)
    for k, belt in enumerate(belts):
        if belt.curve is None or not belt.curve.guide_rails:
            continue
        mine = np.zeros((idx.shape[0] + 2, idx.shape[1] + 2), dtype=bool)
        mine[1:-1, 1:-1] = idx == k
        near = np.zeros(idx.shape, dtype=bool)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                near |= mine[dy:dy + idx.shape[0], dx:dx + idx.shape[1]]
        out |= near & (idx < 0) & _in_sweep(belt.curve, xc, yc)
    return out
