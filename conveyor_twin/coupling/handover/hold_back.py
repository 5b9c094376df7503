"""Hold-back: density flowing into micro tiles waits where the micro parts leave no room.

The macro solver does not see micro parts: :func:`hold_back` (and :func:`hold_back_runs`,
visiting only the inactive cells) pushes density in inactive cells back upstream where the
micro parts there leave no room, and out of sensor windows (closed cells) but for their
entrance behind a macro tile (:func:`entrance_depth`), where it is released.
"""

import math

from numba import njit
import numpy as np

from conveyor_twin.coupling.tiles import count_micro

# Fraction of rho_max at which a window in a sensor window's entrance holds a whole part
# (see entrance_depth): the released stream then reaches the density's own packing.
ENTRANCE_FILL = 0.7


@njit(cache=True)
def upstream_of(vel: np.ndarray, j: int, i: int):
    """Return the upstream neighbour ``(jj, ii)`` of cell ``(j, i)`` against the dominant
    component of the cell velocity ``vel[j, i]`` [m/s]; ``(-1, -1)`` at rest or off the
    grid."""
    ny, nx = vel.shape[0], vel.shape[1]
    vx = vel[j, i, 0]
    vy = vel[j, i, 1]
    if vx == 0.0 and vy == 0.0:
        return -1, -1
    if abs(vx) >= abs(vy):
        jj, ii = j, i - (1 if vx > 0.0 else -1)
    else:
        jj, ii = j - (1 if vy > 0.0 else -1), i
    if jj < 0 or ii < 0 or jj >= ny or ii >= nx:
        return -1, -1
    return jj, ii


@njit(cache=True)
def push_upstream(rho: np.ndarray, solid: np.ndarray, vel: np.ndarray, j: int, i: int,
                  excess: float) -> None:
    """Move ``excess`` [parts/m^2] of cell ``(j, i)`` to its upstream neighbour along the
    dominant component of the cell velocity ``vel[j, i]`` (nothing if the velocity is zero or
    that neighbour is outside the grid or solid)."""
    jj, ii = upstream_of(vel, j, i)
    if jj < 0 or solid[jj, ii]:
        return
    rho[j, i] -= excess
    rho[jj, ii] += excess


@njit(cache=True)
def push_out_of_window(rho: np.ndarray, active: np.ndarray, solid: np.ndarray, vel: np.ndarray,
                       j: int, i: int, closed: np.ndarray, depth: int) -> None:
    """Move all the density of the sensor-window cell ``(j, i)`` to its upstream neighbour
    (see :func:`push_upstream`), unless the cell is in a window's entrance: an active (macro)
    cell lies at most ``depth`` cells upstream of it, through window cells. Density that
    flows straight from a macro tile into a window stays in those entrance cells and is
    released there, as at any macro -> micro boundary (``depth`` deep, so that a release
    window finds a whole part there: see :func:`entrance_depth`)."""
    jj, ii = upstream_of(vel, j, i)
    if jj < 0 or solid[jj, ii] or active[jj, ii]:
        return
    cj, ci = jj, ii
    for _ in range(depth - 1):
        if not closed[cj, ci]:
            break
        cj, ci = upstream_of(vel, cj, ci)
        if cj < 0 or solid[cj, ci]:
            break
        if active[cj, ci]:
            return
    rho[jj, ii] += rho[j, i]
    rho[j, i] = 0.0


def entrance_depth(w: int, rho_max: float, h: float) -> int:
    """Return the depth [cells] of a sensor window's entrance (see :func:`push_out_of_window`).

    The smallest depth in which a release window ``2 w + 1`` cells wide holds a whole part at
    :data:`ENTRANCE_FILL` ``rho_max`` [parts/m^2] (cell edge ``h`` [m]), at most ``2 w + 1``.
    One cell holds ``rho_max h^2``: where a row of ``2 w + 1`` cells holds less than a part
    (parts large against the cells), a one-cell entrance would never release.
    """
    row = (2 * w + 1) * ENTRANCE_FILL * rho_max * h * h
    if row <= 0.0:
        return 1
    return int(min(2 * w + 1, max(1, math.ceil(1.0 / row - 1e-9))))


@njit(cache=True)
def hold_back(rho: np.ndarray, active: np.ndarray, solid: np.ndarray, vel: np.ndarray, ox: float,
              oy: float, h: float, rho_max: float, x: np.ndarray, y: np.ndarray, n: int,
              occ: np.ndarray, windows: tuple) -> None:
    """Push density in inactive cells back upstream where the micro parts leave no room.

    The macro solver does not see micro parts, so density flowing into a micro tile that is
    full (a micro jam) would pile up on top of them. Here the room of an inactive cell is
    ``rho_max h^2`` minus its micro part centres; mass beyond it moves to the upstream
    neighbour (against the larger component of the cell velocity ``vel`` ``(ny, nx, 2)``
    [m/s]), sweeping against the flow so it can travel several cells back to the macro
    cells in one call. Mass moves only within the grid: the total is unchanged. ``occ``
    ``(ny, nx)`` is scratch (micro parts per cell); ``windows`` is ``(closed, depth)``: the
    ``(ny, nx)`` mask of the sensor-window cells and their entrance depth [cells]
    (:func:`push_out_of_window`).
    """
    closed, depth = windows
    ny, nx = rho.shape
    count_micro(x, y, n, ox, oy, h, nx, ny, 1, occ)  # part centres per cell
    hh = h * h
    for jr in range(ny):
        for ir in range(nx):
            # downstream first for flow along +x / +y (the belt's usual direction)
            j = ny - 1 - jr
            i = nx - 1 - ir
            if active[j, i] or rho[j, i] <= 0.0:
                continue
            if closed[j, i]:
                push_out_of_window(rho, active, solid, vel, j, i, closed, depth)
                continue
            room = max(0.0, rho_max * hh - occ[j, i])
            m = rho[j, i] * hh
            if m <= room:
                continue
            push_upstream(rho, solid, vel, j, i, (m - room) / hh)


@njit(cache=True)
def hold_back_runs(rho: np.ndarray, runs: np.ndarray, m: int, active: np.ndarray,
                   solid: np.ndarray,
                   vel: np.ndarray, ox: float, oy: float, h: float, rho_max: float,
                   x: np.ndarray, y: np.ndarray, n: int, occ: np.ndarray,
                   windows: tuple) -> None:
    """:func:`hold_back` visiting only the inactive cells (same order, same result).

    ``runs[:m]`` ``(m, 3)`` holds ``(j, i0, i1)`` row runs of the inactive cells in row-major
    order (:func:`inactive_runs`); they are swept backwards, as :func:`hold_back` sweeps all
    cells. ``occ`` ``(ny, nx)`` is scratch (micro parts per cell).
    """
    closed, depth = windows
    ny, nx = rho.shape
    count_micro(x, y, n, ox, oy, h, nx, ny, 1, occ)  # part centres per cell
    hh = h * h
    cap = rho_max * hh
    for rr in range(m):
        r = m - 1 - rr
        j = runs[r, 0]
        i0 = runs[r, 1]
        i1 = runs[r, 2]
        for ir in range(i1 - i0):
            i = i1 - 1 - ir
            if rho[j, i] <= 0.0:
                continue
            if closed[j, i]:
                push_out_of_window(rho, active, solid, vel, j, i, closed, depth)
                continue
            mass = rho[j, i] * hh
            if mass <= cap - occ[j, i] or mass <= 0.0:
                continue  # within the room max(0, cap - occ)
            room = max(0.0, cap - occ[j, i])
            push_upstream(rho, solid, vel, j, i, (mass - room) / hh)


@njit(cache=True)
def inactive_runs(active: np.ndarray, runs: np.ndarray) -> int:
    """Write the row runs ``(j, i0, i1)`` of the inactive cells, row-major; return how many."""
    ny, nx = active.shape
    m = 0
    for j in range(ny):
        i = 0
        while i < nx:
            if active[j, i]:
                i += 1
                continue
            i0 = i
            while i < nx and not active[j, i]:
                i += 1
            runs[m, 0] = j
            runs[m, 1] = i0
            runs[m, 2] = i
            m += 1
    return m
