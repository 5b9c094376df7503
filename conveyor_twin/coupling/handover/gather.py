"""Gathering: thin density waiting in front of a sensor window leaves as whole parts.

:func:`gather_fronts` collects the remainder in front of a window into one cell (so that a
release window finds a whole part), completes the zone's last part from its thin tail, or lets
a remainder with nothing behind it past the window. :mod:`.reference` holds a plain-Python
version it is tested against.
"""

from numba import njit
import numpy as np

from conveyor_twin.coupling.handover.hold_back import upstream_of
from conveyor_twin.coupling.handover.release import RELEASE_ROUND_OFF

# A front short of a whole part by at most this [parts] takes the rest from the thin tail of
# the zone's last part (see gather_fronts): the part is released once half of it has arrived.
GATHER_SLACK = 0.5
# A front holding less than a part with less than STALE_MASS [parts] in the STALE_CELLS cells
# upstream of it lets its remainder past the window (see gather_fronts).
STALE_MASS = 0.01
STALE_CELLS = 10


@njit(cache=True)
def _downstream(vel: np.ndarray, j: int, i: int):
    """Return the downstream neighbour ``(jj, ii)`` of cell ``(j, i)`` along the dominant
    component of ``vel[j, i]``, and whether the flow there runs along x (``(-1, -1, True)``
    at rest)."""
    vx = vel[j, i, 0]
    vy = vel[j, i, 1]
    if vx == 0.0 and vy == 0.0:
        return -1, -1, True
    if abs(vx) >= abs(vy):
        return j, i + (1 if vx > 0.0 else -1), True
    return j + (1 if vy > 0.0 else -1), i, False


@njit(cache=True)
def _is_front(active: np.ndarray, closed: np.ndarray, solid: np.ndarray, vel: np.ndarray,
              j: int, i: int, along_x: bool) -> bool:
    """True if ``(j, i)`` is an open inactive cell whose downstream neighbour is a closed
    (sensor-window) cell, with the flow along x (``along_x``) or along y."""
    ny, nx = active.shape
    if j < 0 or i < 0 or j >= ny or i >= nx:
        return False
    if active[j, i] or closed[j, i] or solid[j, i]:
        return False
    jj, ii, ax = _downstream(vel, j, i)
    if jj < 0 or ii < 0 or jj >= ny or ii >= nx or ax != along_x:
        return False
    return closed[jj, ii] != 0


@njit(cache=True)
def _upstream_mass(rho: np.ndarray, active: np.ndarray, solid: np.ndarray, vel: np.ndarray,
                   j: int, i: int, cells: int) -> float:
    """Mass [parts / h^2] in up to ``cells`` open inactive cells upstream of ``(j, i)``."""
    total = 0.0
    for _ in range(cells):
        j, i = upstream_of(vel, j, i)
        if j < 0 or solid[j, i] or active[j, i]:
            break
        total += rho[j, i]
    return total


@njit(cache=True)
def _past_window(active: np.ndarray, closed: np.ndarray, solid: np.ndarray, vel: np.ndarray,
                 j: int, i: int):
    """Return the first open cell downstream of the window in front of ``(j, i)``, or
    ``(-1, -1)`` if the window ends at the grid edge, a solid or an active cell."""
    ny, nx = closed.shape
    jj, ii, _ = _downstream(vel, j, i)
    for _ in range(ny + nx):
        if jj < 0 or ii < 0 or jj >= ny or ii >= nx or solid[jj, ii] or active[jj, ii]:
            return -1, -1
        if not closed[jj, ii]:
            return jj, ii
        jj, ii, _ = _downstream(vel, jj, ii)
    return -1, -1


@njit(cache=True)
def gather_fronts(rho: np.ndarray, active: np.ndarray, closed: np.ndarray, solid: np.ndarray,
                  vel: np.ndarray, h: float, border: np.ndarray, w: int, runs: np.ndarray,
                  n_runs: int) -> int:
    """Make the density waiting in front of sensor windows leave; return how many fronts
    changed.

    A front is a run of cells across the flow (a column for flow along x, a row along y) that
    are open and inactive and whose downstream neighbour is closed (:func:`hold_back` keeps
    density out of closed cells). Three cases, else the front waits:

    1. it holds at least one part [parts] but no ``2 w + 1`` consecutive cells of it do (no
       release window ever would): its mass moves to its cell nearest the mass centre;
    2. the last part of the zone: it holds at least ``1 -`` :data:`GATHER_SLACK` and the other
       inactive cells (``runs[:n_runs]``, the row runs of :func:`inactive_runs`) less than a
       part (the thin tail the first-order transport leaves; its last 1 % arrives ~0.7 s late
       on the default cell): it takes the rest from them, proportionally, and gathers as in 1;
    3. a remainder: it holds less than a part and nothing is coming (less than
       :data:`STALE_MASS` in the :data:`STALE_CELLS` cells upstream of each of its cells): its
       mass moves past the window, to the first open cell downstream in the same row (it stays
       where the window ends at the grid edge or a macro cell), and flows on as remainders do.

    The total is kept. ``border`` ``(m, 2)`` lists the open cells next to closed ones (the only
    candidates).
    """
    hh = h * h
    changed = 0
    for k in range(border.shape[0]):
        j0 = border[k, 0]
        i0 = border[k, 1]
        _, _, along_x = _downstream(vel, j0, i0)
        if not _is_front(active, closed, solid, vel, j0, i0, along_x):
            continue
        # only from the first cell of a front (lowest row / column)
        dj, di = (1, 0) if along_x else (0, 1)
        if _is_front(active, closed, solid, vel, j0 - dj, i0 - di, along_x):
            continue
        total = 0.0
        moment = 0.0
        best = 0.0
        length = 0
        j, i = j0, i0
        while _is_front(active, closed, solid, vel, j, i, along_x):
            m = rho[j, i] * hh
            total += m
            moment += m * length
            # the window of 2 w + 1 cells ending here
            win = 0.0
            for b in range(min(length + 1, 2 * w + 1)):
                win += rho[j - b * dj, i - b * di] * hh
            best = max(best, win)
            length += 1
            j += dj
            i += di
        if total <= 0.0 or best >= 1.0 - RELEASE_ROUND_OFF:
            continue
        centre = moment / total  # [cells from the first]
        if total < 1.0 - RELEASE_ROUND_OFF:
            other = 0.0
            if total >= 1.0 - GATHER_SLACK:
                for r in range(n_runs):
                    for ii in range(runs[r, 1], runs[r, 2]):
                        other += rho[runs[r, 0], ii]
                other = other * hh - total  # [parts], the front left out
            take = min(other, 1.0 - total)
            if other < 1.0 and take > 0.0 and total + take >= 1.0 - RELEASE_ROUND_OFF:
                # case 2: the rest of the last part from its tail
                keep = 1.0 - take / other
                for r in range(n_runs):
                    for ii in range(runs[r, 1], runs[r, 2]):
                        rho[runs[r, 0], ii] *= keep
                total += take  # (the front's own cells were scaled too: set below)
            else:
                # case 3, or wait
                coming = 0.0
                for b in range(length):
                    coming += _upstream_mass(rho, active, solid, vel, j0 + b * dj,
                                             i0 + b * di, STALE_CELLS)
                if coming * hh >= STALE_MASS:
                    continue
                moved = False
                for b in range(length):
                    jb, ib = j0 + b * dj, i0 + b * di
                    if rho[jb, ib] == 0.0:
                        continue
                    jp, ip = _past_window(active, closed, solid, vel, jb, ib)
                    if jp < 0:
                        continue
                    rho[jp, ip] += rho[jb, ib]
                    rho[jb, ib] = 0.0
                    moved = True
                if moved:
                    changed += 1
                continue
        # cases 1 and 2: everything into the cell nearest the mass centre
        c = min(length - 1, max(0, int(centre + 0.5)))
        for b in range(length):
            rho[j0 + b * dj, i0 + b * di] = 0.0
        rho[j0 + c * dj, i0 + c * di] = total / hh
        changed += 1
    return changed


@njit(cache=True)
def border_cells(closed: np.ndarray, out: np.ndarray) -> int:
    """Write the open cells 4-adjacent to a closed cell into ``out`` ``(ny * nx, 2)``,
    row-major; return how many."""
    ny, nx = closed.shape
    m = 0
    for j in range(ny):
        for i in range(nx):
            if closed[j, i]:
                continue
            if ((j > 0 and closed[j - 1, i]) or (j + 1 < ny and closed[j + 1, i])
                    or (i > 0 and closed[j, i - 1]) or (i + 1 < nx and closed[j, i + 1])):
                out[m, 0] = j
                out[m, 1] = i
                m += 1
    return m
