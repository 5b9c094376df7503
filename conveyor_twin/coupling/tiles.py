"""The ``auto`` zone policy: square tiles switch micro <-> macro by density, with hysteresis.

A tile turns macro when its density exceeds ``to_macro_density`` and micro when it drops
below ``to_micro_density`` [parts/m^2], at most once per ``min_dwell`` [s]; tiles within
``sensor_margin`` [m] of a light barrier or of any position of an actuator are sensor windows
and stay micro, so discrete signals and actuator contacts stay exact. Micro tiles count part
centres, macro tiles integrate the density; the density is over the tile's area in the zone.

Free flow (``free_flow_slip`` > 0): a micro tile whose parts ride with the belt, i.e. whose mean
slip ``min(1, |v - v_belt| / |v_belt|)`` (``v_belt`` the macro grid's velocity at the part's
cell, sliding along obstacles included; 1 where the belt is slower than
:data:`FREE_FLOW_MIN_SPEED`) is below ``free_flow_slip``, does not turn macro at any density.
Parts on the belt without contacts keep their exact gaps from one sensor window to the next,
which the macro transport would smear; a tile where a queue forms (parts slower than the belt)
still turns macro. It costs micro steps for dense free flow, so it is off by default.
"""

import math
from typing import Sequence

from numba import njit
import numpy as np

from conveyor_twin.cell.model import Actuator, Cell, LightBarrier, Zone
from conveyor_twin.macro import grid as _grid

# Steps between two evaluations of the tile densities.
CHECK_STEPS = 10
# Belt speeds below this [m/s] give no free flow (a part there slips by 1).
FREE_FLOW_MIN_SPEED = 1e-3


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
    nty, ntx = mass.shape
    hh = h * h
    # per tile: rows ascending, cells ascending within a row (the summation order is fixed)
    for j in range(ny):
        ty = j // tc
        for tx in range(ntx):
            acc = mass[ty, tx]
            for i in range(tx * tc, min(nx, (tx + 1) * tc)):
                acc += rho[j, i] * hh
            mass[ty, tx] = acc


@njit(cache=True)
def slip_per_tile(x: np.ndarray, y: np.ndarray, vx: np.ndarray, vy: np.ndarray, n: int,
                  ox: float, oy: float, h: float, vcell: np.ndarray, tc: int,
                  slip: np.ndarray) -> None:
    """Sum the parts' slip ``min(1, |v - v_belt| / |v_belt|)`` per tile (``slip`` ``(nty,
    ntx)``, cleared here; ``vcell`` ``(ny, nx, 2)`` the cell-centre belt velocity [m/s])."""
    slip[:, :] = 0.0
    ny, nx = vcell.shape[0], vcell.shape[1]
    for k in range(n):
        fx = (x[k] - ox) / h
        fy = (y[k] - oy) / h
        if fx < 0.0 or fy < 0.0 or fx >= nx or fy >= ny:
            continue
        i, j = int(fx), int(fy)
        bx, by = vcell[j, i, 0], vcell[j, i, 1]
        speed = math.sqrt(bx * bx + by * by)
        s = 1.0
        if speed > FREE_FLOW_MIN_SPEED:
            s = min(1.0, math.sqrt((vx[k] - bx) ** 2 + (vy[k] - by) ** 2) / speed)
        slip[j // tc, i // tc] += s


@njit(cache=True)
def decide_tiles(parts: tuple, grid: tuple, tiles: tuple, step: int, thresholds: tuple) -> int:
    """Switch the tiles whose density crossed a threshold; return how many switched.

    Tile density [parts/m^2]: the integrated ``rho`` of macro tiles, the micro part centres
    of the others, over ``area`` [m^2]. A micro tile that is not ``locked`` turns macro above
    ``to_macro`` unless it is free flow (mean slip below ``free_flow_slip``, see the module
    docstring; 0: never), a macro tile turns micro below ``to_micro`` or when locked, each at
    least ``dwell`` steps after its last switch (``last_switch``, updated).

    :param parts: ``(x, y, vx, vy, n)``: the micro parts [m, m/s] and their count.
    :param grid: ``(ox, oy, h, rho, vcell)``: origin and cell edge [m], density
        [parts/m^2], cell velocity [m/s].
    :param tiles: ``(tc, counts, mass, slip, area, macro, locked, last_switch)``: tile edge
        [cells], work per tile, modes.
    :param thresholds: ``(dwell, to_macro, to_micro, free_flow_slip)`` [steps, parts/m^2,
        parts/m^2, m/s].
    """
    x, y, vx, vy, n = parts
    ox, oy, h, rho, vcell = grid
    tc, counts, mass, slip, area, macro, locked, last_switch = tiles
    dwell, to_macro, to_micro, free_flow_slip = thresholds
    ny, nx = rho.shape
    count_micro(x, y, n, ox, oy, h, nx, ny, tc, counts)
    mass_per_tile(rho, h, tc, mass)
    if free_flow_slip > 0.0:
        slip_per_tile(x, y, vx, vy, n, ox, oy, h, vcell, tc, slip)
    nty, ntx = macro.shape
    switched = 0
    for ty in range(nty):
        for tx in range(ntx):
            if step - last_switch[ty, tx] < dwell:
                continue
            if macro[ty, tx]:
                if mass[ty, tx] / area[ty, tx] < to_micro or locked[ty, tx]:
                    macro[ty, tx] = False
                    last_switch[ty, tx] = step
                    switched += 1
            elif (not locked[ty, tx] and counts[ty, tx] / area[ty, tx] > to_macro
                  and not (free_flow_slip > 0.0
                           and slip[ty, tx] < free_flow_slip * counts[ty, tx])):
                macro[ty, tx] = True
                last_switch[ty, tx] = step
                switched += 1
    return switched


@njit(cache=True)
def fill_cell_mask(macro: np.ndarray, tc: int, active: np.ndarray) -> None:
    """Write the ``(ny, nx)`` uint8 mask of the cells of macro tiles into ``active``."""
    ny, nx = active.shape
    for j in range(ny):
        for i in range(nx):
            active[j, i] = 1 if macro[j // tc, i // tc] else 0


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
        self.slip = np.zeros((self.nty, self.ntx))
        self.switches = 0

    def cell_mask(self) -> np.ndarray:
        """Return the ``(ny, nx)`` uint8 mask of the cells of macro tiles."""
        active = np.zeros((self.grid.ny, self.grid.nx), dtype=np.uint8)
        fill_cell_mask(self.macro, self.tc, active)
        return active

    def decide(self, step: int, x: np.ndarray, y: np.ndarray, vx: np.ndarray,
               vy: np.ndarray, n: int, rho: np.ndarray, vcell: np.ndarray) -> bool:
        """Update the tile modes from the densities (and the parts' slip against the belt
        velocity ``vcell`` [m/s], ``(ny, nx, 2)``); return True if any tile switched."""
        g = self.grid
        p = self.params
        switched = decide_tiles(
            (x, y, vx, vy, n), (g.origin_x, g.origin_y, g.h, rho, vcell),
            (self.tc, self.counts, self.mass, self.slip, self.area, self.macro, self.locked,
             self.last_switch),
            step, (self.dwell_steps, float(p.to_macro_density), float(p.to_micro_density),
                   float(p.free_flow_slip)))
        self.switches += switched
        return switched > 0

    def force(self, macro: np.ndarray, step: int) -> None:
        """Set the tile modes (tests, tools); sensor windows stay micro."""
        new = np.asarray(macro, dtype=bool) & ~self.locked
        changed = new != self.macro
        self.macro[:] = new
        self.last_switch[changed] = step
        self.switches += int(changed.sum())
