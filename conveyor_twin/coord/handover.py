"""Compiled kernels of the micro <-> macro hand-over (no ROS imports, allocation-free).

Every kernel works on one macro grid: density ``rho`` ``(ny, nx)`` [parts/m^2], origin
``(ox, oy)`` [m], cell edge ``h`` [m], an ``active`` mask ``(ny, nx)`` (1: the cell is simulated
macro now) and the grid's ``solid`` mask (1: obstacle or engaged actuator).

- :func:`capture_mask` marks the micro parts whose centre lies in an active cell;
- :func:`deposit_disc` adds exactly one part's worth of mass over the footprint disc of a
  captured part, restricted to active fluid cells (renormalised, so the amount is exact);
- :func:`hold_back` pushes density in inactive (micro) cells back upstream where the micro
  parts there leave no room, and out of sensor windows; :func:`gather_fronts` collects the
  thin remainder waiting in front of a window so that it can leave as a whole part;
- :func:`window_candidate` finds where an accumulator window holds at least one part, and
  :func:`window_subtract` removes one part from it (proportionally, so nothing goes negative).
"""

import math

from numba import njit
import numpy as np

from conveyor_twin.coord.tiles import count_micro
from conveyor_twin.micro.sources import place
from conveyor_twin.micro.state import C_N, P_X, P_Y, PT_BRAD

# Sub-samples per cell edge when the footprint disc is rasterised.
DEPOSIT_SAMPLES = 8
# Margin [m] of the test that skips cells apart from a footprint disc (far above round-off).
_DISC_MARGIN = 1e-9
# Bucket edge over the largest search reach of a release (keeps round-off off the edge).
BUCKET_SLACK = 1.01
# A window holding a part but for this much round-off [parts] releases it (the last part of
# a zone is often 1 - 1e-13 after thousands of additions; the ledger check allows 1e-9).
RELEASE_ROUND_OFF = 1e-11
# A front short of a whole part by at most this [parts] takes the rest from the thin tail of
# the zone's last part (see gather_fronts): the part is released once half of it has arrived.
GATHER_SLACK = 0.5
# A front holding less than a part with less than STALE_MASS [parts] in the STALE_CELLS cells
# upstream of it lets its remainder past the window (see gather_fronts).
STALE_MASS = 0.01
STALE_CELLS = 10
# Buckets of the micro-part lookup per macro grid (the edge grows when more would be needed).
BUCKETS = 1 << 14


@njit(cache=True)
def capture_mask(x: np.ndarray, y: np.ndarray, n: int, ox: float, oy: float, h: float,
                 active: np.ndarray, mask: np.ndarray) -> int:
    """Set ``mask[k]`` for the parts ``k < n`` whose centre is in an active cell; return how many.

    ``mask`` is only written (True) for captured parts; the caller clears it before.
    """
    ny, nx = active.shape
    count = 0
    for k in range(n):
        fx = (x[k] - ox) / h
        fy = (y[k] - oy) / h
        if fx < 0.0 or fy < 0.0 or fx >= nx or fy >= ny:
            continue
        if active[int(fy), int(fx)]:
            mask[k] = True
            count += 1
    return count


@njit(cache=True)
def _covered_samples(i: int, j: int, ox: float, oy: float, h: float, px: float, py: float,
                     r2: float, s: int) -> int:
    """Return how many of the s x s sample points of cell (i, j) lie in the disc of squared
    radius ``r2`` [m^2] at ``(px, py)`` [m]."""
    w = 0
    for a in range(s):
        yy = oy + (j + (a + 0.5) / s) * h - py
        for b in range(s):
            xx = ox + (i + (b + 0.5) / s) * h - px
            if xx * xx + yy * yy <= r2:
                w += 1
    return w


@njit(cache=True)
def deposit_disc(rho: np.ndarray, active: np.ndarray, solid: np.ndarray, ox: float, oy: float,
                 h: float, px: float, py: float, radius: float, amount: float) -> None:
    """Add ``amount`` parts over the disc of ``radius`` [m] at ``(px, py)`` [m], exactly.

    Weights are the disc's area in each active fluid cell (sub-sampled); if none is left the
    nearest active fluid cell takes it all (rings of growing size, row-major order).
    """
    ny, nx = rho.shape
    ic = min(max(int((px - ox) / h), 0), nx - 1)
    jc = min(max(int((py - oy) / h), 0), ny - 1)
    rc = int(radius / h) + 1
    s = DEPOSIT_SAMPLES
    r2 = radius * radius
    # cells whose box is clearly apart from the disc's box hold no sample in it (skipped)
    reach = radius + _DISC_MARGIN
    total = 0.0
    for j in range(max(0, jc - rc), min(ny, jc + rc + 1)):
        if oy + j * h - py > reach or py - (oy + (j + 1) * h) > reach:
            continue
        for i in range(max(0, ic - rc), min(nx, ic + rc + 1)):
            if not active[j, i] or solid[j, i]:
                continue
            if ox + i * h - px > reach or px - (ox + (i + 1) * h) > reach:
                continue
            total += _covered_samples(i, j, ox, oy, h, px, py, r2, s)
    inv = 1.0 / (h * h)
    if total > 0.0:
        scale = amount * inv / total
        for j in range(max(0, jc - rc), min(ny, jc + rc + 1)):
            if oy + j * h - py > reach or py - (oy + (j + 1) * h) > reach:
                continue
            for i in range(max(0, ic - rc), min(nx, ic + rc + 1)):
                if not active[j, i] or solid[j, i]:
                    continue
                if ox + i * h - px > reach or px - (ox + (i + 1) * h) > reach:
                    continue
                w = _covered_samples(i, j, ox, oy, h, px, py, r2, s)
                if w:
                    rho[j, i] += scale * w
        return
    for ring in range(max(nx, ny)):
        for j in range(max(0, jc - ring), min(ny, jc + ring + 1)):
            for i in range(max(0, ic - ring), min(nx, ic + ring + 1)):
                if max(abs(j - jc), abs(i - ic)) != ring:
                    continue
                if active[j, i] and not solid[j, i]:
                    rho[j, i] += amount * inv
                    return
    rho[jc, ic] += amount * inv  # no active fluid cell at all: keep the mass anyway


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
                       j: int, i: int) -> None:
    """Move all the density of the sensor-window cell ``(j, i)`` to its upstream neighbour
    (see :func:`push_upstream`), unless that neighbour is active (macro): density that flows
    straight from a macro tile into a window stays in the window's entrance cells and is
    released there, as at any macro -> micro boundary."""
    jj, ii = upstream_of(vel, j, i)
    if jj < 0 or solid[jj, ii] or active[jj, ii]:
        return
    rho[jj, ii] += rho[j, i]
    rho[j, i] = 0.0


@njit(cache=True)
def hold_back(rho: np.ndarray, active: np.ndarray, solid: np.ndarray, vel: np.ndarray, ox: float,
              oy: float, h: float, rho_max: float, x: np.ndarray, y: np.ndarray, n: int,
              occ: np.ndarray, closed: np.ndarray) -> None:
    """Push density in inactive cells back upstream where the micro parts leave no room.

    The macro solver does not see micro parts, so density flowing into a micro tile that is
    full (a micro jam) would pile up on top of them. Here the room of an inactive cell is
    ``rho_max h^2`` minus its micro part centres; mass beyond it moves to the upstream
    neighbour (against the larger component of the cell velocity ``vel`` ``(ny, nx, 2)``
    [m/s]), sweeping against the flow so it can travel several cells back to the macro
    cells in one call. Mass moves only within the grid: the total is unchanged. ``occ``
    ``(ny, nx)`` is scratch (micro parts per cell).
    """
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
                push_out_of_window(rho, active, solid, vel, j, i)
                continue
            room = max(0.0, rho_max * hh - occ[j, i])
            m = rho[j, i] * hh
            if m <= room:
                continue
            push_upstream(rho, solid, vel, j, i, (m - room) / hh)


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


@njit(cache=True)
def take_mask(rho: np.ndarray, mask: np.ndarray, h: float) -> float:
    """Remove the mass of the cells where ``mask`` is set; return it [parts]."""
    ny, nx = rho.shape
    hh = h * h
    total = 0.0
    for j in range(ny):
        for i in range(nx):
            if mask[j, i] and rho[j, i] != 0.0:
                total += rho[j, i] * hh
                rho[j, i] = 0.0
    return total


@njit(cache=True)
def take_cells(rho: np.ndarray, cells: np.ndarray, h: float) -> float:
    """:func:`take_mask` over the flat row-major indices ``cells`` (ascending) of the mask."""
    nx = rho.shape[1]
    hh = h * h
    total = 0.0
    for c in cells:
        j = c // nx
        i = c - j * nx
        if rho[j, i] != 0.0:
            total += rho[j, i] * hh
            rho[j, i] = 0.0
    return total


@njit(cache=True)
def window_candidate(acc: np.ndarray, skip: np.ndarray, unit: float, ranges: np.ndarray,
                     cur: np.ndarray, w: int, threshold: float, thr: np.ndarray,
                     out: np.ndarray) -> bool:
    """Find the next cell whose window holds a part, scanning only the cell ranges given.

    ``acc`` holds mass (``acc * unit`` [parts] per cell); cells where ``skip`` is set are
    not part of any window (macro cells when ``acc`` is the density). ``ranges`` ``(m, 4)``
    holds ``(j0, j1, i0, i1)`` blocks of cells to scan (row-major within a block); ``cur``
    ``(2,)`` is the cursor (block, flat index in the block) to start from and is left on the
    cell found. The window is the ``(2 w + 1)^2`` block around the cell; only cells holding at
    least ``threshold / (2 w + 1)^2`` are tried as centres. ``out`` receives
    ``(j, i, sum [parts], centroid_j, centroid_i)`` (centroid in cells, mass-weighted).
    Return False when no window from the cursor on holds ``threshold + thr[j, i]`` [parts]
    (less :data:`RELEASE_ROUND_OFF`).
    """
    ny, nx = acc.shape
    min_centre = threshold / ((2 * w + 1) * (2 * w + 1))
    while cur[0] < ranges.shape[0]:
        j0, j1, i0, i1 = ranges[cur[0], 0], ranges[cur[0], 1], ranges[cur[0], 2], ranges[cur[0], 3]
        bw = i1 - i0
        js = j0 + cur[1] // bw  # the cursor's cell (row-major in the block)
        ic = i0 + cur[1] % bw
        for j in range(js, j1):
            for i in range(ic if j == js else i0, i1):
                # a window holding a part has a cell with 1 / (2 w + 1)^2 of it: only
                # windows centred on such cells are tried (thin density is not scanned)
                if acc[j, i] * unit < min_centre or skip[j, i]:
                    continue
                total = 0.0
                cj = 0.0
                ci = 0.0
                for jj in range(max(0, j - w), min(ny, j + w + 1)):
                    for ii in range(max(0, i - w), min(nx, i + w + 1)):
                        if skip[jj, ii]:
                            continue
                        a = acc[jj, ii] * unit
                        total += a
                        cj += a * jj
                        ci += a * ii
                if total >= threshold + thr[j, i] - RELEASE_ROUND_OFF:
                    out[0] = j
                    out[1] = i
                    out[2] = total
                    out[3] = cj / total
                    out[4] = ci / total
                    cur[1] = (j - j0) * bw + (i - i0)
                    return True
        cur[0] += 1
        cur[1] = 0
    return False


@njit(cache=True)
def window_subtract(acc: np.ndarray, skip: np.ndarray, j: int, i: int, w: int, total: float,
                    amount: float) -> None:
    """Remove ``amount`` [parts] from the window around ``(j, i)`` holding ``total``
    [parts], proportionally (cells where ``skip`` is set are not touched)."""
    ny, nx = acc.shape
    keep = 1.0 - amount / total
    for jj in range(max(0, j - w), min(ny, j + w + 1)):
        for ii in range(max(0, i - w), min(nx, i + w + 1)):
            if not skip[jj, ii]:
                acc[jj, ii] *= keep


@njit(cache=True)
def release_windows(acc: np.ndarray, skip: np.ndarray, unit: float, ranges: np.ndarray, w: int,
                    ox: float, oy: float, h: float, vel: np.ndarray, offsets: np.ndarray,
                    d: float, nx_: float, ny_: float, along_flow: bool, grid: np.ndarray,
                    active: np.ndarray, max_fail: int, cand: np.ndarray, rot: np.ndarray,
                    near: np.ndarray, bhead: np.ndarray, bnext: np.ndarray,
                    fifo: np.ndarray, fstate: np.ndarray,
                    released_by_type: np.ndarray, thr: np.ndarray, rng: np.ndarray, counters,
                    ids, ptype, P,
                    pt, shp, shp_verts, act_state, act_verts, va, vb, out) -> np.ndarray:
    """Release whole parts wherever a window of ``acc`` holds one; return (released, failed,
    windows tried).

    Only the cells of ``ranges`` are scanned (see :func:`window_candidate`; ``skip`` and
    ``unit`` as there). A part goes to ``(ox + (ci + 0.5) h, oy + (cj + 0.5) h)`` [m] (the
    window's mass centre ``(cj, ci)`` in cells) with the velocity ``vel[round(cj), round(ci)]``
    [m/s]; if it would overlap, the ``offsets`` (along, out) in units of ``d`` [m] relative to
    the outward direction are tried, ``out >= 0`` only (downstream). The outward direction is
    ``(nx_, ny_)``, or with ``along_flow`` the direction of the local velocity (``(nx_, ny_)``
    where it is zero). Spots whose centre lies in an active (macro) cell of the grid
    (``grid = (x0, y0, h)``, mask ``active``) are refused, so a released part is not captured
    again. After ``max_fail`` refused placements the rest waits. ``rot[0]`` rotates the first
    offset tried from one part to the next (stride 7), so consecutive parts spread over the
    window. The micro parts near a window are looked up in buckets (:func:`bucket_parts`;
    ``near`` ``(capacity,)``, ``bnext`` ``(capacity,)`` and ``bhead`` are scratch), built at
    the first window that needs them; parts placed here are added to them.

    Part types: ``fifo`` is the zone's ring buffer of the types of the parts deposited,
    ``fstate = (head, count, untyped)``; each released part takes the type at the head (FIFO
    per zone); with the buffer empty (mass from a prescribed inflow) type 0, counted in
    ``untyped``. ``released_by_type`` counts the releases per type.

    Arrival phases: the window around cell ``(j, i)`` releases its next part once it holds
    ``1 + thr[j, i]`` [parts] (``thr`` shaped like ``acc``); after each release ``thr[j, i]``
    is redrawn as ``rng[0] * u`` with ``u`` uniform in [0, 1) from the deterministic generator
    whose state is ``rng[1]`` (see :func:`next_uniform`). So neighbouring windows fed by the
    same uniform density do not release in lock-step. The remaining arguments are those of
    :func:`conveyor_twin.micro.sources.place`.
    """
    res = np.zeros(3, dtype=np.int64)
    cur = np.zeros(2, dtype=np.int64)
    gnx = active.shape[1]
    gny = active.shape[0]
    k = offsets.shape[0]
    omax = 0.0  # largest |offset| [diameters] (the reach of the spots around a window)
    for oi in range(k):
        omax = max(omax, abs(offsets[oi, 0]), abs(offsets[oi, 1]))
    # bucket edge [m]: above the reach of any part type's search below
    brad = 0.0
    for tt in range(pt.shape[0]):
        brad = max(brad, pt[tt, PT_BRAD])
    bbox = np.zeros(5)
    bbox[2] = BUCKET_SLACK * (d * (omax + 1.0) + 2.0 * brad + d)
    built = False
    while res[1] < max_fail:
        if not window_candidate(acc, skip, unit, ranges, cur, w, 1.0, thr, cand):
            break
        res[2] += 1
        j = int(cand[0])
        i = int(cand[1])
        total = cand[2]
        cj = cand[3]
        ci = cand[4]
        x = ox + (ci + 0.5) * h
        y = oy + (cj + 0.5) * h
        vj = min(max(int(cj + 0.5), 0), vel.shape[0] - 1)
        vi = min(max(int(ci + 0.5), 0), vel.shape[1] - 1)
        vx = vel[vj, vi, 0]
        vy = vel[vj, vi, 1]
        ex = nx_
        ey = ny_
        if along_flow:
            sp = math.sqrt(vx * vx + vy * vy)
            if sp > 0.0:
                ex = vx / sp
                ey = vy / sp
        tx, ty = -ey, ex
        t = 0
        if fstate[1] > 0:
            t = fifo[fstate[0]]
        rt = pt[t, PT_BRAD]
        ok = False
        # any spot off the macro cells? (else the window waits, without a look at the parts)
        usable = False
        for oi in range(k):
            if offsets[oi, 1] < 0.0:
                continue
            px = x + d * (offsets[oi, 0] * tx + offsets[oi, 1] * ex)
            py = y + d * (offsets[oi, 0] * ty + offsets[oi, 1] * ey)
            fx = (px - grid[0]) / grid[2]
            fy = (py - grid[1]) / grid[2]
            if not (0.0 <= fx < gnx and 0.0 <= fy < gny and active[int(fy), int(fx)]):
                usable = True
                break
        if not usable:
            cur[1] += 1
            continue
        # the parts near the window, so most candidates are refused without a full check
        reach = d * (omax + 1.0) + 2.0 * rt + d
        if not built:
            bucket_parts(P, counters[C_N], grid[0], grid[1], gnx * grid[2], gny * grid[2],
                         bbox, bhead, bnext)
            built = True
        m = near_parts(P, x, y, reach, bbox, bhead, bnext, near)
        for o in range(k):
            oi = (o + rot[0]) % k
            along = offsets[oi, 0]
            outw = offsets[oi, 1]
            if outw < 0.0:
                continue
            if res[1] >= max_fail:
                break
            px = x + d * (along * tx + outw * ex)
            py = y + d * (along * ty + outw * ey)
            fx = (px - grid[0]) / grid[2]
            fy = (py - grid[1]) / grid[2]
            if 0.0 <= fx < gnx and 0.0 <= fy < gny and active[int(fy), int(fx)]:
                continue
            clear = True
            for e in range(m):
                q = near[e]
                rr = rt + pt[ptype[q], PT_BRAD]
                ddx = P[P_X, q] - px
                ddy = P[P_Y, q] - py
                if ddx * ddx + ddy * ddy < rr * rr:
                    clear = False
                    break
            if not clear:
                continue  # bounding circles overlap: refused without the full check
            pid = place(t, px, py, 0.0, vx, vy, 0.0, counters, ids, ptype, P, pt, shp,
                        shp_verts, act_state, act_verts, va, vb, out)
            if pid != 0:
                ok = True
                bucket_add(P, counters[C_N] - 1, bbox, bhead, bnext)
                break
            res[1] += 1
        rot[0] = (rot[0] + 7) % k
        if ok:
            window_subtract(acc, skip, j, i, w, total, min(1.0, total))
            res[0] += 1
            released_by_type[t] += 1
            if fstate[1] > 0:
                fstate[0] = (fstate[0] + 1) % fifo.size
                fstate[1] -= 1
            else:
                fstate[2] += 1
            if rng[0] > 0.0:
                thr[j, i] = rng[0] * next_uniform(rng)
            continue
        cur[1] += 1
    return res


@njit(cache=True)
def _bucket_of(P: np.ndarray, q: int, bbox: np.ndarray) -> int:
    """Return the bucket of part ``q`` (coordinates clamped to the bucket grid)."""
    fx = (P[P_X, q] - bbox[0]) / bbox[2]
    fy = (P[P_Y, q] - bbox[1]) / bbox[2]
    nbx = int(bbox[3])
    nby = int(bbox[4])
    bx = min(int(fx), nbx - 1) if fx >= 0.0 else 0
    by = min(int(fy), nby - 1) if fy >= 0.0 else 0
    return by * nbx + bx


@njit(cache=True)
def bucket_parts(P: np.ndarray, n: int, x0: float, y0: float, width: float, height: float,
                 bbox: np.ndarray, bhead: np.ndarray, bnext: np.ndarray) -> None:
    """Sort the parts ``k < n`` into square buckets over the box ``(x0, y0)`` + ``(width,
    height)`` [m] with a margin of one bucket (parts outside go to the border buckets).

    ``bbox`` ``(5,)``: the bucket edge [m] in ``bbox[2]`` on entry (doubled until the buckets
    fit ``bhead``); on return ``(bx0, by0, edge, nbx, nby)``. ``bhead`` holds each bucket's
    first part (-1: none), ``bnext`` each part's next one.
    """
    edge = bbox[2]
    while True:
        nbx = int((width + 2.0 * edge) / edge) + 1
        nby = int((height + 2.0 * edge) / edge) + 1
        if nbx * nby <= bhead.size:
            break
        edge *= 2.0
    bbox[0] = x0 - edge
    bbox[1] = y0 - edge
    bbox[2] = edge
    bbox[3] = nbx
    bbox[4] = nby
    bhead[:nbx * nby] = -1
    for q in range(n):
        bucket_add(P, q, bbox, bhead, bnext)


@njit(cache=True)
def bucket_add(P: np.ndarray, q: int, bbox: np.ndarray, bhead: np.ndarray,
               bnext: np.ndarray) -> None:
    """Add part ``q`` to its bucket (see :func:`bucket_parts`)."""
    b = _bucket_of(P, q, bbox)
    bnext[q] = bhead[b]
    bhead[b] = q


@njit(cache=True)
def near_parts(P: np.ndarray, x: float, y: float, reach: float, bbox: np.ndarray,
               bhead: np.ndarray, bnext: np.ndarray, near: np.ndarray) -> int:
    """Write the parts with ``|dx|, |dy| < reach`` [m] of ``(x, y)`` [m] to ``near``; return
    how many. ``reach`` must not exceed the bucket edge (the 3 x 3 buckets around hold them).
    """
    nbx = int(bbox[3])
    nby = int(bbox[4])
    fx = (x - bbox[0]) / bbox[2]
    fy = (y - bbox[1]) / bbox[2]
    cx = min(int(fx), nbx - 1) if fx >= 0.0 else 0
    cy = min(int(fy), nby - 1) if fy >= 0.0 else 0
    m = 0
    for by in range(max(0, cy - 1), min(nby, cy + 2)):
        for bx in range(max(0, cx - 1), min(nbx, cx + 2)):
            q = bhead[by * nbx + bx]
            while q >= 0:
                if abs(P[P_X, q] - x) < reach and abs(P[P_Y, q] - y) < reach:
                    near[m] = q
                    m += 1
                q = bnext[q]
    return m


@njit(cache=True)
def next_uniform(rng: np.ndarray) -> float:
    """Advance the generator state ``rng[1]`` (a 48-bit LCG kept exactly in a float64) and
    return a uniform number in [0, 1)."""
    s = np.int64(rng[1])
    s = (s * np.int64(25214903917) + np.int64(11)) & np.int64((1 << 48) - 1)
    rng[1] = float(s)
    return float(s >> np.int64(16)) / float(1 << 32)


@njit(cache=True)
def deposit_many(rho: np.ndarray, active: np.ndarray, solid: np.ndarray, ox: float, oy: float,
                 h: float, x: np.ndarray, y: np.ndarray, types: np.ndarray,
                 radius_of_type: np.ndarray) -> None:
    """Deposit one part's worth for every ``(x[k], y[k])`` [m] (:func:`deposit_disc`, in order)."""
    for k in range(x.size):
        deposit_disc(rho, active, solid, ox, oy, h, x[k], y[k], radius_of_type[types[k]], 1.0)


@njit(cache=True)
def deposit_push(rho: np.ndarray, active: np.ndarray, solid: np.ndarray, ox: float, oy: float,
                 h: float, x: np.ndarray, y: np.ndarray, types: np.ndarray,
                 radius_of_type: np.ndarray, fifo: np.ndarray, fstate: np.ndarray,
                 by_type: np.ndarray) -> None:
    """Deposit the captured parts (:func:`deposit_many`) and append their types to the FIFO.

    ``fifo``/``fstate`` as in :func:`release_windows` (the caller has grown the ring so the
    ``x.size`` new entries fit); ``by_type`` counts the captures per type.
    """
    size = fifo.size
    tail = fstate[0] + fstate[1]
    for k in range(x.size):
        t = types[k]
        deposit_disc(rho, active, solid, ox, oy, h, x[k], y[k], radius_of_type[t], 1.0)
        fifo[(tail + k) % size] = t
        by_type[t] += 1
    fstate[1] += x.size


@njit(cache=True)
def accumulate_faces(outflow: np.ndarray, face_sink: np.ndarray, acc: np.ndarray,
                     sides: np.ndarray) -> int:
    """Add the boundary outflow [parts] of the faces that do not lead into a sink to ``acc``.

    ``outflow``, ``face_sink`` and ``acc`` are ``(n_boundary,)`` in the grid's boundary-face
    order, ``sides`` ``(4, 2)`` the face ranges of the left, right, bottom and top sides.
    A side without any outflow is left alone. Return a bit mask of the sides (bit ``s``)
    where a sink face has outflow (the caller sums it, as NumPy does).
    """
    flags = 0
    for s in range(4):
        a, b = sides[s, 0], sides[s, 1]
        any_out = False
        for f in range(a, b):
            if outflow[f] != 0.0:
                any_out = True
                if face_sink[f]:
                    flags |= 1 << s
        if not any_out:
            continue
        for f in range(a, b):
            acc[f] += 0.0 if face_sink[f] else outflow[f]
    return flags


@njit(cache=True)
def side_max(acc: np.ndarray, sides: np.ndarray, out: np.ndarray) -> None:
    """Write the largest accumulator value of each side to ``out`` ``(4,)`` [parts]."""
    for s in range(4):
        m = -np.inf
        for f in range(sides[s, 0], sides[s, 1]):
            m = max(m, acc[f])
        out[s] = m


@njit(cache=True)
def hold_back_runs(rho: np.ndarray, runs: np.ndarray, m: int, active: np.ndarray,
                   solid: np.ndarray,
                   vel: np.ndarray, ox: float, oy: float, h: float, rho_max: float,
                   x: np.ndarray, y: np.ndarray, n: int, occ: np.ndarray,
                   closed: np.ndarray) -> None:
    """:func:`hold_back` visiting only the inactive cells (same order, same result).

    ``runs[:m]`` ``(m, 3)`` holds ``(j, i0, i1)`` row runs of the inactive cells in row-major
    order (:func:`inactive_runs`); they are swept backwards, as :func:`hold_back` sweeps all
    cells. ``occ`` ``(ny, nx)`` is scratch (micro parts per cell).
    """
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
                push_out_of_window(rho, active, solid, vel, j, i)
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


@njit(cache=True)
def micro_blocks(macro: np.ndarray, tc: int, ny: int, nx: int, out: np.ndarray) -> int:
    """Write the cell blocks ``(j0, j1, i0, i1)`` of the micro tiles to ``out``; return how many.

    The tiles come row-major (tile ``(ty, tx)`` covers cells ``ty tc .. (ty + 1) tc`` by
    ``tx tc .. (tx + 1) tc``, clipped to the grid), scanned row-major within a block as
    :func:`window_candidate` does. Neighbouring blocks are merged where the merged block is
    scanned in the same cell order: side by side when one cell high, one above the other
    when both span the whole grid width.
    """
    nty, ntx = macro.shape
    m = 0
    for ty in range(nty):
        j0 = ty * tc
        j1 = min(ny, j0 + tc)
        for tx in range(ntx):
            if macro[ty, tx]:
                continue
            i0 = tx * tc
            i1 = min(nx, i0 + tc)
            if (m > 0 and j1 - j0 == 1 and out[m - 1, 0] == j0 and out[m - 1, 1] == j1
                    and out[m - 1, 3] == i0):
                out[m - 1, 3] = i1
            else:
                out[m, 0] = j0
                out[m, 1] = j1
                out[m, 2] = i0
                out[m, 3] = i1
                m += 1
            # a block spanning the grid width continues the one above it if that does too
            if (m > 1 and out[m - 1, 2] == 0 and out[m - 1, 3] == nx and out[m - 2, 2] == 0
                    and out[m - 2, 3] == nx and out[m - 2, 1] == out[m - 1, 0]):
                out[m - 2, 1] = out[m - 1, 1]
                m -= 1
    return m
