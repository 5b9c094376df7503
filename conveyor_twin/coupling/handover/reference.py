"""Plain-Python references of the release and the gathering (slow, readable; for the tests).

:func:`gather_fronts_ref` is :func:`~conveyor_twin.coupling.handover.gather.gather_fronts` and
:func:`release_windows_ref` is :func:`~conveyor_twin.coupling.handover.release.release_windows`,
written for reading: fronts and windows are found by scanning every cell, micro parts are
checked one by one (no buckets), and each case is a function of its own. They add the same
numbers in the same order as the kernels, so the tests compare the results bit for bit. The
placement of a part itself is :func:`conveyor_twin.micro.sources.place` in both.
"""

import math
from typing import List, Optional, Tuple

import numpy as np

from conveyor_twin.coupling.handover.gather import GATHER_SLACK, STALE_CELLS, STALE_MASS
from conveyor_twin.coupling.handover.release import next_uniform, RELEASE_ROUND_OFF
from conveyor_twin.micro.sources import place
from conveyor_twin.micro.state import C_N, P_X, P_Y, PT_BRAD

Cell = Tuple[int, int]


# --- flow directions --------------------------------------------------------------------------

def _flow_step(vel: np.ndarray, j: int, i: int) -> Optional[Tuple[int, int, bool]]:
    """Return the step ``(dj, di)`` downstream along the dominant component of ``vel[j, i]``
    and whether it runs along x; None at rest."""
    vx, vy = vel[j, i, 0], vel[j, i, 1]
    if vx == 0.0 and vy == 0.0:
        return None
    if abs(vx) >= abs(vy):
        return 0, (1 if vx > 0.0 else -1), True
    return (1 if vy > 0.0 else -1), 0, False


def _on_grid(shape: Tuple[int, int], j: int, i: int) -> bool:
    return 0 <= j < shape[0] and 0 <= i < shape[1]


def _upstream(vel: np.ndarray, j: int, i: int) -> Optional[Cell]:
    step = _flow_step(vel, j, i)
    if step is None or not _on_grid(vel.shape[:2], j - step[0], i - step[1]):
        return None
    return j - step[0], i - step[1]


# --- gathering --------------------------------------------------------------------------------

def _is_front(active, closed, solid, vel, j: int, i: int, along_x: bool) -> bool:
    """An open inactive cell whose downstream neighbour (flow along ``along_x``) is closed."""
    if not _on_grid(active.shape, j, i) or active[j, i] or closed[j, i] or solid[j, i]:
        return False
    step = _flow_step(vel, j, i)
    along = True if step is None else step[2]
    if step is None or along != along_x:
        return False
    jj, ii = j + step[0], i + step[1]
    return _on_grid(active.shape, jj, ii) and closed[jj, ii] != 0


def _fronts(rho, active, closed, solid, vel) -> List[List[Cell]]:
    """Return the fronts in row-major order of their first cells, each as its cells in order
    (down the column for flow along x, along the row for flow along y)."""
    fronts = []
    ny, nx = rho.shape
    for j in range(ny):
        for i in range(nx):
            step = _flow_step(vel, j, i)
            along_x = True if step is None else step[2]
            if not _is_front(active, closed, solid, vel, j, i, along_x):
                continue
            dj, di = (1, 0) if along_x else (0, 1)
            if _is_front(active, closed, solid, vel, j - dj, i - di, along_x):
                continue  # not the first cell of its front
            cells = []
            jj, ii = j, i
            while _is_front(active, closed, solid, vel, jj, ii, along_x):
                cells.append((jj, ii))
                jj, ii = jj + dj, ii + di
            fronts.append(cells)
    return fronts


def _best_window(masses: List[float], w: int) -> float:
    """The most any ``2 w + 1`` consecutive cells of a front hold [parts] (summed from the
    last cell of each window back)."""
    best = 0.0
    for k in range(len(masses)):
        win = 0.0
        for b in range(min(k + 1, 2 * w + 1)):
            win += masses[k - b]
        best = max(best, win)
    return best


def _inactive_sum(rho, active) -> float:
    total = 0.0
    for j in range(rho.shape[0]):
        for i in range(rho.shape[1]):
            if not active[j, i]:
                total += rho[j, i]
    return total


def _upstream_mass(rho, active, solid, vel, cell: Cell) -> float:
    """Mass [parts / h^2] in up to :data:`STALE_CELLS` open inactive cells upstream."""
    total = 0.0
    for _ in range(STALE_CELLS):
        cell = _upstream(vel, *cell)
        if cell is None or solid[cell] or active[cell]:
            break
        total += rho[cell]
    return total


def _past_window(active, closed, solid, vel, cell: Cell) -> Optional[Cell]:
    """The first open cell downstream of the window in front of ``cell`` (None: the window
    ends at the grid edge, a solid or an active cell)."""
    j, i = cell
    for _ in range(closed.shape[0] + closed.shape[1]):
        step = _flow_step(vel, j, i)
        if step is None:
            return None
        j, i = j + step[0], i + step[1]
        if not _on_grid(closed.shape, j, i) or solid[j, i] or active[j, i]:
            return None
        if not closed[j, i]:
            return j, i
    return None


def gather_fronts_ref(rho: np.ndarray, active: np.ndarray, closed: np.ndarray,
                      solid: np.ndarray, vel: np.ndarray, h: float, w: int) -> int:
    """Do what :func:`~conveyor_twin.coupling.handover.gather.gather_fronts` does; return how
    many fronts changed (``rho`` [parts/m^2] updated in place)."""
    hh = h * h
    changed = 0
    for cells in _fronts(rho, active, closed, solid, vel):
        masses = [rho[c] * hh for c in cells]
        total = 0.0
        moment = 0.0
        for k, m in enumerate(masses):
            total += m
            moment += m * k
        if total <= 0.0 or _best_window(masses, w) >= 1.0 - RELEASE_ROUND_OFF:
            continue  # empty, or a release window takes it as it is
        centre = moment / total
        if total < 1.0 - RELEASE_ROUND_OFF:
            # the zone's last part: the rest from the thin tail in the other inactive cells
            other = 0.0
            if total >= 1.0 - GATHER_SLACK:
                other = _inactive_sum(rho, active) * hh - total
            take = min(other, 1.0 - total)
            if other < 1.0 and take > 0.0 and total + take >= 1.0 - RELEASE_ROUND_OFF:
                rho[active == 0] *= 1.0 - take / other
                total += take
            else:
                # a remainder with nothing coming moves past the window; else it waits
                coming = 0.0
                for c in cells:
                    coming += _upstream_mass(rho, active, solid, vel, c)
                if coming * hh >= STALE_MASS:
                    continue
                moved = False
                for c in cells:
                    past = _past_window(active, closed, solid, vel, c)
                    if rho[c] == 0.0 or past is None:
                        continue
                    rho[past] += rho[c]
                    rho[c] = 0.0
                    moved = True
                changed += int(moved)
                continue
        # a whole part: into the cell nearest the mass centre
        k = min(len(cells) - 1, max(0, int(centre + 0.5)))
        for c in cells:
            rho[c] = 0.0
        rho[cells[k]] = total / hh
        changed += 1
    return changed


# --- release ----------------------------------------------------------------------------------

def _window(acc, skip, unit: float, j: int, i: int, w: int) -> Tuple[float, float, float]:
    """Return the mass [parts] of the window around ``(j, i)`` and its centre (cj, ci) sums."""
    ny, nx = acc.shape
    total = cj = ci = 0.0
    for jj in range(max(0, j - w), min(ny, j + w + 1)):
        for ii in range(max(0, i - w), min(nx, i + w + 1)):
            if not skip[jj, ii]:
                a = acc[jj, ii] * unit
                total += a
                cj += a * jj
                ci += a * ii
    return total, cj, ci


def _next_window(acc, skip, unit: float, thr, cells: List[Cell], start: int, w: int):
    """Return ``(index, total, cj, ci)`` of the first cell from ``cells[start]`` on whose
    window holds a part (less round-off), or None."""
    min_centre = 1.0 / ((2 * w + 1) * (2 * w + 1))
    for k in range(start, len(cells)):
        j, i = cells[k]
        if acc[j, i] * unit < min_centre or skip[j, i]:
            continue  # a window holding a part has a cell with 1 / (2 w + 1)^2 of it
        total, cj, ci = _window(acc, skip, unit, j, i, w)
        if total >= 1.0 + thr[j, i] - RELEASE_ROUND_OFF:
            return k, total, cj / total, ci / total
    return None


def _in_active(grid, active, px: float, py: float) -> bool:
    fx = (px - grid[0]) / grid[2]
    fy = (py - grid[1]) / grid[2]
    return (0.0 <= fx < active.shape[1] and 0.0 <= fy < active.shape[0]
            and bool(active[int(fy), int(fx)]))


def _clear(micro, t: int, px: float, py: float) -> bool:
    """True if no micro part's bounding circle overlaps that of a part of type ``t``."""
    counters, ids, ptype, P, pt = micro[:5]
    rt = pt[t, PT_BRAD]
    for q in range(counters[C_N]):
        rr = rt + pt[ptype[q], PT_BRAD]
        ddx = P[P_X, q] - px
        ddy = P[P_Y, q] - py
        if ddx * ddx + ddy * ddy < rr * rr:
            return False
    return True


def release_windows_ref(window: tuple, w: int, spots: tuple, max_fail: int, rot: np.ndarray,
                        zone: tuple, micro: tuple) -> np.ndarray:
    """Do what :func:`~conveyor_twin.coupling.handover.release.release_windows` does (same
    tuples, ``rot`` instead of its scratch); return (released, failed, windows tried)."""
    acc, skip, unit, thr, ranges = window
    ox, oy, h, vel, offsets, d, nx_, ny_, along_flow, grid, active = spots
    fifo, fstate, released_by_type, rng = zone
    cells = [(j, i) for j0, j1, i0, i1 in ranges for j in range(j0, j1) for i in range(i0, i1)]
    spots_out = [(a, o) for a, o in offsets if o >= 0.0]
    k = len(offsets)
    res = np.zeros(3, dtype=np.int64)
    cursor = 0
    while res[1] < max_fail:
        found = _next_window(acc, skip, unit, thr, cells, cursor, w)
        if found is None:
            break
        cursor, total, cj, ci = found
        res[2] += 1
        j, i = cells[cursor]
        x = ox + (ci + 0.5) * h
        y = oy + (cj + 0.5) * h
        vj = min(max(int(cj + 0.5), 0), vel.shape[0] - 1)
        vi = min(max(int(ci + 0.5), 0), vel.shape[1] - 1)
        vx, vy = vel[vj, vi, 0], vel[vj, vi, 1]
        ex, ey = nx_, ny_
        speed = math.sqrt(vx * vx + vy * vy)
        if along_flow and speed > 0.0:
            ex, ey = vx / speed, vy / speed
        tx, ty = -ey, ex
        t = fifo[fstate[0]] if fstate[1] > 0 else 0

        def spot(along, outw):
            return (x + d * (along * tx + outw * ex), y + d * (along * ty + outw * ey))

        if all(_in_active(grid, active, *spot(a, o)) for a, o in spots_out):
            cursor += 1  # every spot on macro cells: the window waits
            continue
        placed = False
        for o in range(k):
            along, outw = offsets[(o + rot[0]) % k]
            if outw < 0.0:
                continue
            if res[1] >= max_fail:
                break
            px, py = spot(along, outw)
            if _in_active(grid, active, px, py) or not _clear(micro, t, px, py):
                continue
            if place(t, px, py, 0.0, vx, vy, 0.0, micro) != 0:
                placed = True
                break
            res[1] += 1
        rot[0] = (rot[0] + 7) % k
        if not placed:
            cursor += 1
            continue
        # one part less in the window (proportionally), the type from the FIFO
        keep = 1.0 - min(1.0, total) / total
        for jj in range(max(0, j - w), min(acc.shape[0], j + w + 1)):
            for ii in range(max(0, i - w), min(acc.shape[1], i + w + 1)):
                if not skip[jj, ii]:
                    acc[jj, ii] *= keep
        res[0] += 1
        released_by_type[t] += 1
        if fstate[1] > 0:
            fstate[0] = (fstate[0] + 1) % fifo.size
            fstate[1] -= 1
        else:
            fstate[2] += 1
        if rng[0] > 0.0:
            thr[j, i] = rng[0] * next_uniform(rng)
    return res
