"""Release: wherever a window of density holds a whole part, a micro part is placed.

:func:`window_candidate` finds where an accumulator window holds at least one part,
:func:`release_windows` places a micro part there (with the type at the head of the zone's
FIFO) and :func:`window_subtract` removes one part from the window (proportionally, so nothing
goes negative). :mod:`.reference` holds a plain-Python version it is tested against.
"""

import math

from numba import njit
import numpy as np

from conveyor_twin.coupling.handover.buckets import (bucket_add, bucket_parts, BUCKET_SLACK,
                                                     near_parts)
from conveyor_twin.micro.sources import place
from conveyor_twin.micro.state import C_N, P_X, P_Y, PT_BRAD

# A window holding a part but for this much round-off [parts] releases it (the last part of
# a zone is often 1 - 1e-13 after thousands of additions; the ledger check allows 1e-9).
RELEASE_ROUND_OFF = 1e-11


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
def next_uniform(rng: np.ndarray) -> float:
    """Advance the generator state ``rng[1]`` (a 48-bit LCG kept exactly in a float64) and
    return a uniform number in [0, 1)."""
    s = np.int64(rng[1])
    s = (s * np.int64(25214903917) + np.int64(11)) & np.int64((1 << 48) - 1)
    rng[1] = float(s)
    return float(s >> np.int64(16)) / float(1 << 32)


@njit(cache=True)
def release_windows(window: tuple, w: int, spots: tuple, max_fail: int, scratch: tuple,
                    zone: tuple, micro: tuple) -> np.ndarray:
    """Release whole parts wherever a window of ``acc`` holds one; return (released, failed,
    windows tried).

    The arguments come in tuples by concept (unpacked here, no copies):

    - ``window = (acc, skip, unit, thr, ranges)``: what is scanned;
    - ``spots = (ox, oy, h, vel, offsets, d, nx_, ny_, along_flow, grid, active)``: where a
      part goes;
    - ``scratch = (cand, rot, near, bhead, bnext)``;
    - ``zone = (fifo, fstate, released_by_type, rng)``: the zone's part types and generator;
    - ``micro = (counters, ids, ptype, P, pt, shp, shp_verts, act_state, act_verts, va, vb,
      out)``: the micro state, as :func:`conveyor_twin.micro.sources.place` takes it.

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
    acc, skip, unit, thr, ranges = window
    ox, oy, h, vel, offsets, d, nx_, ny_, along_flow, grid, active = spots
    cand, rot, near, bhead, bnext = scratch
    fifo, fstate, released_by_type, rng = zone
    counters, ids, ptype, P, pt, shp, shp_verts, act_state, act_verts, va, vb, out = micro
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
            pid = place(t, px, py, 0.0, vx, vy, 0.0, micro)
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
