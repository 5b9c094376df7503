"""The ``auto`` zone policy: square tiles switch micro <-> macro by density, with hysteresis.

A tile turns macro when its density exceeds ``to_macro_density`` and micro when it drops
below ``to_micro_density`` [parts/m^2], at most once per ``min_dwell`` [s]; tiles within
``sensor_margin`` [m] of a light barrier or of any position of an actuator are sensor windows
and stay micro, so discrete signals and actuator contacts stay exact. Micro tiles count part
centres, macro tiles integrate the density; the density is over the tile's area in the zone.
"""

import math
from typing import Sequence

from numba import njit
import numpy as np

from conveyor_twin.cell.model import Actuator, Cell, LightBarrier, Zone
from conveyor_twin.macro import grid as _grid

# Steps between two evaluations of the tile densities.
CHECK_STEPS = 10


@njit(cache=True)
def count_micro(x: np.ndarray, y: np.ndarray, n: int, ox: float, oy: float, h: float,
                nx: int, ny: int, tc: int, counts: np.ndarray) -> None:
    """Count the part centres per tile (``counts`` ``(nty, ntx)``, cleared here)."""
    counts[:, :] = 0.0
    for k in range(n):
        fx = (x[k] - ox) / h
        fy = (y[k] - oy) / h
        if fx < 0.0 or fy < 0.0 or fx >= nx or fy >= ny:
            continue
        counts[int(fy) // tc, int(fx) // tc] += 1.0


@njit(cache=True)
def mass_per_tile(rho: np.ndarray, h: float, tc: int, mass: np.ndarray) -> None:
    """Integrate the density per tile [parts] (``mass`` ``(nty, ntx)``, cleared here)."""
    mass[:, :] = 0.0
    ny, nx = rho.shape
    hh = h * h
    for j in range(ny):
        for i in range(nx):
            mass[j // tc, i // tc] += rho[j, i] * hh


def _segment_rect_near(a, b, rect, margin: float) -> bool:
    """True if the segment ``a``-``b`` comes within ``margin`` of ``rect`` (sampled)."""
    x0, y0, x1, y1 = rect
    steps = max(2, int(math.hypot(b[0] - a[0], b[1] - a[1]) / 0.005) + 1)
    for s in np.linspace(0.0, 1.0, steps):
        px, py = a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])
        dx = max(x0 - px, 0.0, px - x1)
        dy = max(y0 - py, 0.0, py - y1)
        if dx * dx + dy * dy <= margin * margin:
            return True
    return False


def _actuator_reach(actuator: Actuator) -> np.ndarray:
    """Return the corners of the actuator's footprint over its whole position range."""
    low, high = actuator.position_range
    polys = [_grid.actuator_polygon(actuator, p) for p in np.linspace(low, high, 9)]
    return np.concatenate(polys, axis=0)


def sensor_window(tile_rects: np.ndarray, barriers: Sequence[LightBarrier],
                  actuators: Sequence[Actuator], margin: float) -> np.ndarray:
    """Return a bool mask of the tiles that stay micro (near a barrier or an actuator)."""
    lock = np.zeros(len(tile_rects), dtype=bool)
    for k, rect in enumerate(tile_rects):
        for b in barriers:
            if _segment_rect_near(b.start, b.end, rect, margin):
                lock[k] = True
        for a in actuators:
            pts = _actuator_reach(a)
            x0, y0 = pts.min(axis=0) - margin
            x1, y1 = pts.max(axis=0) + margin
            if x0 <= rect[2] and rect[0] <= x1 and y0 <= rect[3] and rect[1] <= y1:
                lock[k] = True
    return lock


class AutoTiles:
    """Tile state of one ``auto`` zone on its macro grid.

    :param cell: the validated cell. :param zone: the zone. :param grid: its macro grid.
    """

    def __init__(self, cell: Cell, zone: Zone, grid: _grid.Grid) -> None:
        p = zone.auto
        self.params = p
        self.h = grid.h
        self.tc = max(1, int(round(p.tile / grid.h)))
        self.nty = -(-grid.ny // self.tc)
        self.ntx = -(-grid.nx // self.tc)
        self.grid = grid
        rects = []
        area = np.zeros((self.nty, self.ntx))
        for ty in range(self.nty):
            for tx in range(self.ntx):
                j0, i0 = ty * self.tc, tx * self.tc
                j1, i1 = min(grid.ny, j0 + self.tc), min(grid.nx, i0 + self.tc)
                rects.append((grid.origin_x + i0 * grid.h, grid.origin_y + j0 * grid.h,
                              grid.origin_x + i1 * grid.h, grid.origin_y + j1 * grid.h))
                area[ty, tx] = (j1 - j0) * (i1 - i0) * grid.h * grid.h
        self.area = area
        self.locked = sensor_window(np.array(rects), cell.light_barriers, cell.actuators,
                                    p.sensor_margin).reshape(self.nty, self.ntx)
        self.macro = np.zeros((self.nty, self.ntx), dtype=bool)
        self.last_switch = np.full((self.nty, self.ntx), -(1 << 40), dtype=np.int64)
        self.dwell_steps = int(round(p.min_dwell / cell.settings.step))
        self.counts = np.zeros((self.nty, self.ntx))
        self.mass = np.zeros((self.nty, self.ntx))
        self.switches = 0

    def cell_mask(self) -> np.ndarray:
        """Return the ``(ny, nx)`` uint8 mask of the cells of macro tiles."""
        full = np.repeat(np.repeat(self.macro, self.tc, axis=0), self.tc, axis=1)
        return full[:self.grid.ny, :self.grid.nx].astype(np.uint8)

    def decide(self, step: int, x: np.ndarray, y: np.ndarray, n: int,
               rho: np.ndarray) -> bool:
        """Update the tile modes from the densities; return True if any tile switched."""
        g = self.grid
        count_micro(x, y, n, g.origin_x, g.origin_y, g.h, g.nx, g.ny, self.tc, self.counts)
        mass_per_tile(rho, g.h, self.tc, self.mass)
        density = np.where(self.macro, self.mass, self.counts) / self.area
        ready = (step - self.last_switch) >= self.dwell_steps
        up = ~self.macro & ~self.locked & ready & (density > self.params.to_macro_density)
        down = self.macro & ready & ((density < self.params.to_micro_density) | self.locked)
        if not (up.any() or down.any()):
            return False
        self.macro[up] = True
        self.macro[down] = False
        self.last_switch[up | down] = step
        self.switches += int(up.sum() + down.sum())
        return True

    def force(self, macro: np.ndarray, step: int) -> None:
        """Set the tile modes (tests, tools); sensor windows stay micro."""
        new = np.asarray(macro, dtype=bool) & ~self.locked
        changed = new != self.macro
        self.macro[:] = new
        self.last_switch[changed] = step
        self.switches += int(changed.sum())
