"""Numba kernels of one split sweep: face fluxes, slope limiter, donor and receiver limits.

All kernels work in place on preallocated arrays (``ny x nx`` density, staggered face arrays as
documented in :mod:`conveyor_twin.macro.grid`). A face *amount* ``a`` is the density change the
face causes in a substep, ``a = w dt / h * rho_face`` [parts/m^2]: the cell left of (below) the
face loses ``a``, the cell right of (above) it gains ``a``; ``a h^2`` parts cross the face.

Scheme (LeVeque, *Finite Volume Methods for Hyperbolic Problems*, ch. 6 and 19):

- ``upwind``: ``rho_face`` = donor cell value (Godunov for linear advection, first order).
- ``limited``: ``rho_face = rho_D +- 0.5 (1 - |c|) slope_D`` with ``c = w dt / h`` and the limited
  slope of the donor cell (second order where smooth, TVD; the Lax-Wendroff correction written
  as a reconstruction). Slopes are zero next to solid cells and at the domain edge.

Capped flux (Hoher et al., ``rho v (1 - H(rho - rho_max))``), in supply/demand (Godunov) form:
donor sends ``a`` as above; the receiver accepts at most its free capacity in this substep,
``rho_max - rho_R + out_R``, where ``out_R`` is what the receiver itself sends on along the same
direction in the same substep. Faces are visited downstream first (positive faces from the right
end, negative faces from the left end), so ``out_R`` is final when it is used; a cell fed from
both sides shares its capacity in proportion to the two demands. This is exactly "the flux is
cut by the amount that would lift the receiver above rho_max", i.e. H evaluated on the
receiver's post-sweep density, so ``0 <= rho <= rho_max`` holds to round-off after every sweep,
a packed block moves at belt speed (the flux ``u rho`` is increasing, so nothing is cut while
nothing would overflow), and a blocked front queues back at the Rankine-Hugoniot speed
``u rho_in / (rho_max - rho_in)``.
"""

import math

from numba import njit
import numpy as np

LIMITER_MINMOD = 0
LIMITER_MC = 1
LIMITER_VANLEER = 2
# Relative margin of the pre-check that bounds where a receiver cut can start: a cell's
# ``rho + inflow`` and its cut condition are rounded differently, by a few ulps of the
# densities involved; 1e-12 covers densities up to ~1000 rho_max (above rho_max every cell
# with inflow passes the pre-check anyway).
EXCESS_MARGIN = 1e-12


@njit(cache=True)
def limited_slope(dl: float, dr: float, limiter: int) -> float:
    """Return the limited cell difference from the left and right differences [parts/m^2].

    Written with selects rather than branches so the slope loops vectorise.
    """
    adl = abs(dl)
    adr = abs(dr)
    if limiter == LIMITER_MINMOD:
        m = min(adl, adr)
    elif limiter == LIMITER_MC:
        m = min(2.0 * adl, 2.0 * adr, 0.5 * (adl + adr))
    else:
        total = adl + adr
        m = 2.0 * adl * adr / total if total > 0.0 else 0.0
    return math.copysign(m, dl) if dl * dr > 0.0 else 0.0


@njit(cache=True)
def _cap_line_pos(a: np.ndarray, rho: np.ndarray, n: int, rho_max: float,
                  has_negative: bool, lo: int, hi: int, seed: np.ndarray) -> None:
    """Receiver cut of one line (faces ``0..n``, cells ``0..n-1``).

    :param has_negative: False if no face amount is negative (the second pass is skipped).
    :param hi: one past the last cell that could overflow (:func:`_line_excess`): the
        downstream-first pass starts there, as every face downstream of it is left unchanged
        (a cell that cannot overflow, with its downstream face unchanged, keeps its inflow).
    :param lo: the first cell whose ``rho + inflow`` exceeds ``rho_max (1 - EXCESS_MARGIN)``
        (:func:`_line_excess`): no face upstream of it meets its cut condition on the
        demands (the margin covers the rounding of both tests), so only chains of cuts reach
        there.
    :param seed: uint8 work ``(>= n + 1,)``.

    A face is cut only if its receiver overflows, with the receiver's downstream face as it is
    when the face is visited; that face differs from its demand only if it was cut itself. So
    a branch-free pass first marks the faces whose cut condition holds on the demands
    (``seed``), and the sequential downstream-first pass visits only those and the chains of
    faces upstream of a cut face; the others would be visited without effect. The same
    arithmetic as a visit of every face, so the same results bit for bit.
    """
    for f in range(lo, hi):
        af = a[f]
        ar = a[f + 1]
        base = rho_max - rho[f]
        cap_c = max(base, 0.0)
        cap_o = max(base + ar, 0.0)
        conv = ar < 0.0
        t = af - ar if conv else af
        c = cap_c if conv else cap_o
        seed[f] = (af > 0.0) & (t > c)
    f = hi - 1
    dirty = False
    while f >= 0:
        if not dirty:
            while f >= lo and seed[f] == 0:
                f -= 1
            if f < lo:
                break
        af = a[f]
        dirty = False
        if af > 0.0:
            ar = a[f + 1]
            if ar < 0.0:
                cap = rho_max - rho[f]
                total = af - ar
                if cap < 0.0:
                    cap = 0.0
                if total > cap:
                    s = cap / total
                    a[f] = af * s
                    a[f + 1] = ar * s
                    dirty = True
            else:
                cap = rho_max - rho[f] + ar
                if cap < 0.0:
                    cap = 0.0
                if af > cap:
                    a[f] = cap
                    dirty = True
        f -= 1
    if not has_negative:
        return
    for f in range(1, n + 1):
        af = a[f]
        if af >= 0.0:
            continue
        al = a[f - 1]
        if al > 0.0:
            continue  # converging: shared in the first pass
        cap = rho_max - rho[f - 1] - al
        if cap < 0.0:
            cap = 0.0
        if -af > cap:
            a[f] = -cap


@njit(cache=True)
def _line_excess(a: np.ndarray, rho: np.ndarray, n: int, rho_max: float):
    """Return ``(lo, hi)``: ``hi`` is one past the last cell of one line whose
    ``rho + inflow`` exceeds ``rho_max`` (0: none), ``lo`` the first whose ``rho + inflow``
    exceeds ``rho_max (1 - EXCESS_MARGIN)`` (``n``: none).

    Written as branch-free 32-bit integer min/max-reductions so that it vectorises (64-bit
    integer min/max has no AVX2 instruction).
    """
    thr = rho_max * (1.0 - EXCESS_MARGIN)
    none = np.int32(n)
    lo = none
    hi = np.int32(0)
    for i in range(n):
        v = rho[i] + max(a[i], 0.0) - min(a[i + 1], 0.0)
        ii = np.int32(i)
        hi = max(hi, ii + np.int32(1) if v > rho_max else np.int32(0))
        lo = min(lo, ii if v > thr else none)
    return int(lo), int(hi)


@njit(cache=True)
def _pair_excess(a_lo: np.ndarray, a_hi: np.ndarray, rho: np.ndarray, n: int,
                 rho_max: float) -> int:
    """As :func:`_line_excess` for a row of a y sweep with its lower and upper faces."""
    count = 0
    for i in range(n):
        v = rho[i] + max(a_lo[i], 0.0) - min(a_hi[i], 0.0)
        count += v > rho_max
    return count


@njit(cache=True)
def _line_overdraw(a: np.ndarray, rho: np.ndarray, n: int) -> int:
    """Count the cells of one line that would send more than they hold."""
    count = 0
    for i in range(n):
        v = max(a[i + 1], 0.0) - min(a[i], 0.0)
        count += v > rho[i]
    return count


@njit(cache=True)
def _pair_overdraw(a_lo: np.ndarray, a_hi: np.ndarray, rho: np.ndarray, n: int) -> int:
    """As :func:`_line_overdraw` for a row of a y sweep."""
    count = 0
    for i in range(n):
        v = max(a_hi[i], 0.0) - min(a_lo[i], 0.0)
        count += v > rho[i]
    return count


@njit(cache=True)
def _donor_line(a: np.ndarray, rho: np.ndarray, n: int) -> None:
    """Scale the outflows of every cell of one line so none sends more than it holds."""
    for i in range(n):
        out = 0.0
        if a[i + 1] > 0.0:
            out += a[i + 1]
        if a[i] < 0.0:
            out -= a[i]
        if out > rho[i]:
            s = rho[i] / out if out > 0.0 else 0.0
            if a[i + 1] > 0.0:
                a[i + 1] *= s
            if a[i] < 0.0:
                a[i] *= s


@njit(cache=True)
def sweep_x(rho: np.ndarray, wx: np.ndarray, solid: np.ndarray, dts: float, h: float,
            rho_max: float, capped: bool, limited: bool, limiter: int, in_rate: np.ndarray,
            in_acc: np.ndarray, out_acc: np.ndarray, a: np.ndarray, slope: np.ndarray,
            seed: np.ndarray) -> None:
    """Advance ``rho`` by one x sweep of length ``dts`` [s] in place.

    :param rho: ``(ny, nx)`` density [parts/m^2].
    :param wx: ``(ny, nx + 1)`` total face velocity [m/s] (belt field plus operator).
    :param solid: ``(ny, nx)`` uint8. :param h: cell edge [m].
    :param capped: apply the receiver-capacity cut. :param limited: second-order scheme.
    :param limiter: ``LIMITER_*``.
    :param in_rate: ``(2 (nx + ny),)`` prescribed inflow per boundary face [parts/s].
    :param in_acc: accepted inflow per boundary face [parts], accumulated.
    :param out_acc: outflow per boundary face [parts], accumulated.
    :param a: work ``(ny, nx + 1)``; :param slope: work ``(ny, nx)``; :param seed: uint8
        work ``(>= nx + 1,)``.

    The donor and receiver passes run only on rows where some cell could be overdrawn or
    overflow, which a cheap check after the demand pass detects.
    """
    ny, nx = rho.shape
    k = dts / h
    area = h * h
    in_scale = dts / area
    for j in range(ny):
        r = rho[j]
        aj = a[j]
        wj = wx[j]
        sol = solid[j]
        # Boundary faces: upwind outflow, or the prescribed inflow.
        negative = 0
        w = wj[0]
        if w < 0.0:
            aj[0] = w * k * r[0]
        else:
            aj[0] = in_rate[j] * in_scale if sol[0] == 0 else 0.0
        w = wj[nx]
        if w > 0.0:
            aj[nx] = w * k * r[nx - 1]
        else:
            aj[nx] = -in_rate[ny + j] * in_scale if sol[nx - 1] == 0 else 0.0
        if limited:
            sj = slope[j]
            sj[0] = 0.0
            sj[nx - 1] = 0.0
            for i in range(1, nx - 1):
                s = 0.0
                if sol[i - 1] == 0 and sol[i + 1] == 0:
                    s = limited_slope(r[i] - r[i - 1], r[i + 1] - r[i], limiter)
                sj[i] = s
            for f in range(1, nx):
                w = wj[f]
                c = w * k
                negative += w < 0.0
                if w > 0.0:
                    aj[f] = c * (r[f - 1] + 0.5 * (1.0 - c) * sj[f - 1])
                elif w < 0.0:
                    aj[f] = c * (r[f] - 0.5 * (1.0 + c) * sj[f])
                else:
                    aj[f] = 0.0
            if _line_overdraw(aj, r, nx) > 0:
                _donor_line(aj, r, nx)
        else:
            for f in range(1, nx):
                w = wj[f]
                negative += w < 0.0
                aj[f] = w * k * (r[f - 1] if w > 0.0 else r[f])
        if capped:
            lo, hi = _line_excess(aj, r, nx, rho_max)
            if hi > 0:
                negative += (aj[0] < 0.0) + (aj[nx] < 0.0)
                _cap_line_pos(aj, r, nx, rho_max, negative > 0, lo, hi, seed)
        for i in range(nx):
            r[i] += aj[i] - aj[i + 1]
        a0 = aj[0]
        if a0 > 0.0:
            in_acc[j] += a0 * area
        else:
            out_acc[j] -= a0 * area
        an = aj[nx]
        if an > 0.0:
            out_acc[ny + j] += an * area
        else:
            in_acc[ny + j] -= an * area


@njit(cache=True, inline='always')
def _cell_row_range(yr: np.ndarray, j: int, ny: int, nx: int):
    """Return the columns ``[lo, hi)`` of cell row ``j`` that a y face can change.

    Hull of the ranges of its two face rows; the grid's edge face rows count as full.
    """
    if j == 0 or j == ny - 1:
        return 0, nx
    lo = yr[j, 0]
    hi = yr[j, 1]
    lo2 = yr[j + 1, 0]
    hi2 = yr[j + 1, 1]
    if hi2 > lo2:
        if hi > lo:
            lo = min(lo, lo2)
            hi = max(hi, hi2)
        else:
            lo = lo2
            hi = hi2
    return lo, hi


@njit(cache=True, inline='always')
def _face_cols(yr: np.ndarray, f: int, ny: int, nx: int):
    """Return the columns ``[lo, hi)`` of y-face row ``f`` that may carry a non-zero amount."""
    if f == 0 or f == ny:
        return 0, nx
    return yr[f, 0], yr[f, 1]


@njit(cache=True)
def y_ranges(uy: np.ndarray, yr: np.ndarray) -> None:
    """Store per y-face row ``f`` the columns ``[lo, hi)`` outside which ``uy[f]`` is zero.

    :param uy: ``(ny + 1, nx)`` face velocities [m/s]; :param yr: int64 ``(ny + 1, 2)``,
        ``(0, 0)`` for a row without velocity.
    """
    nf, nx = uy.shape
    for f in range(nf):
        lo = nx
        hi = 0
        for i in range(nx):
            if uy[f, i] != 0.0:
                lo = min(lo, i)
                hi = i + 1
        if hi <= lo:
            lo = 0
            hi = 0
        yr[f, 0] = lo
        yr[f, 1] = hi


@njit(cache=True)
def sweep_y(rho: np.ndarray, wy: np.ndarray, solid: np.ndarray, dts: float, h: float,
            rho_max: float, capped: bool, limited: bool, limiter: int, in_rate: np.ndarray,
            in_acc: np.ndarray, out_acc: np.ndarray, a: np.ndarray, yr: np.ndarray) -> None:
    """Advance ``rho`` by one y sweep; arguments as :func:`sweep_x` with ``(ny + 1, nx)`` faces.

    :param yr: int64 ``(ny + 1, 2)``: per interior face row ``f`` the columns ``[lo, hi)``
        outside which ``wy[f]`` is zero (:func:`y_ranges`, merged with the operator's faces).
    :param a: work ``(ny + 1, nx)``; its interior face rows must be zero on entry, and are
        left zero (only the ranges ``yr`` are written, and cleared at the end).

    A face of zero velocity has a zero amount and changes nothing (the donor and receiver
    cuts leave zero amounts alone), so demands, slopes, cuts and the update run only on the
    face ranges ``yr`` and the cells next to them: on a belt running along x, only the
    sliding layers in front of obstacles and the operator's faces. The edge face rows are
    computed in full. Rows are visited in the outer loop so every inner loop runs over
    contiguous memory.
    """
    ny, nx = rho.shape
    k = dts / h
    area = h * h
    in_scale = dts / area
    b0 = 2 * ny          # bottom faces
    b1 = 2 * ny + nx     # top faces
    negative = 0
    for i in range(nx):
        w = wy[0, i]
        if w < 0.0:
            a[0, i] = w * k * rho[0, i]
        else:
            a[0, i] = in_rate[b0 + i] * in_scale if solid[0, i] == 0 else 0.0
        w = wy[ny, i]
        if w > 0.0:
            a[ny, i] = w * k * rho[ny - 1, i]
        else:
            a[ny, i] = -in_rate[b1 + i] * in_scale if solid[ny - 1, i] == 0 else 0.0
    if limited:
        for f in range(1, ny):
            for i in range(yr[f, 0], yr[f, 1]):
                w = wy[f, i]
                c = w * k
                negative += w < 0.0
                if w != 0.0:
                    jd = f - 1 if w > 0.0 else f      # donor row
                    s = 0.0
                    if (0 < jd < ny - 1 and solid[jd - 1, i] == 0
                            and solid[jd + 1, i] == 0):
                        s = limited_slope(rho[jd, i] - rho[jd - 1, i],
                                          rho[jd + 1, i] - rho[jd, i], limiter)
                    if w > 0.0:
                        a[f, i] = c * (rho[jd, i] + 0.5 * (1.0 - c) * s)
                    else:
                        a[f, i] = c * (rho[jd, i] - 0.5 * (1.0 + c) * s)
                else:
                    a[f, i] = 0.0
        count = 0
        for j in range(ny):
            lo, hi = _cell_row_range(yr, j, ny, nx)
            count += _pair_overdraw(a[j, lo:hi], a[j + 1, lo:hi], rho[j, lo:hi], hi - lo)
        if count > 0:
            for j in range(ny):
                lo, hi = _cell_row_range(yr, j, ny, nx)
                for i in range(lo, hi):
                    out = max(a[j + 1, i], 0.0) - min(a[j, i], 0.0)
                    if out > rho[j, i]:
                        s = rho[j, i] / out if out > 0.0 else 0.0
                        if a[j + 1, i] > 0.0:
                            a[j + 1, i] *= s
                        if a[j, i] < 0.0:
                            a[j, i] *= s
    if capped or not limited:
        # The upwind demand of face row j + 1 and the overflow check of cell row j in one
        # pass (row j's faces are final once row j + 1's are computed).
        count = 0
        i0 = nx
        i1 = 0
        j0 = ny
        j1 = -1
        for j in range(ny):
            f = j + 1
            if f < ny and not limited:
                for i in range(yr[f, 0], yr[f, 1]):
                    w = wy[f, i]
                    negative += w < 0.0
                    a[f, i] = w * k * (rho[f - 1, i] if w > 0.0 else rho[f, i])
            if not capped:
                continue
            lo, hi = _cell_row_range(yr, j, ny, nx)
            if _pair_excess(a[j, lo:hi], a[j + 1, lo:hi], rho[j, lo:hi], hi - lo,
                            rho_max) > 0:
                count += 1
                j0 = min(j0, j)
                j1 = j
                for i in range(lo, hi):
                    v = rho[j, i] + max(a[j, i], 0.0) - min(a[j + 1, i], 0.0)
                    if v > rho_max:
                        i0 = min(i0, i)
                        i1 = max(i1, i + 1)
        if count > 0:
            for i in range(nx):
                negative += (a[0, i] < 0.0) + (a[ny, i] < 0.0)
            _cap_grid_y(a, rho, rho_max, i0, i1, j0, j1, negative > 0, yr)
    for j in range(ny):
        lo, hi = _cell_row_range(yr, j, ny, nx)
        for i in range(lo, hi):
            rho[j, i] += a[j, i] - a[j + 1, i]
    for i in range(nx):
        a0 = a[0, i]
        if a0 > 0.0:
            in_acc[b0 + i] += a0 * area
        else:
            out_acc[b0 + i] -= a0 * area
        an = a[ny, i]
        if an > 0.0:
            out_acc[b1 + i] += an * area
        else:
            in_acc[b1 + i] -= an * area
    for f in range(1, ny):
        for i in range(yr[f, 0], yr[f, 1]):
            a[f, i] = 0.0


@njit(cache=True)
def _cap_grid_y(a: np.ndarray, rho: np.ndarray, rho_max: float, i0: int, i1: int, j0: int,
                j1: int, has_negative: bool, yr: np.ndarray) -> None:
    """Receiver cut of a y sweep (as :func:`_cap_line_pos`) on the columns ``i0..i1-1``.

    ``j0``, ``j1``: first and last row with an overflowing cell (the cut propagates only
    upstream of them). ``has_negative``: False skips the negative-face pass. ``yr``: face
    ranges of :func:`sweep_y` (amounts are zero outside them and are left alone).
    """
    ny, nx = rho.shape
    for f in range(j1, -1, -1):
        lo, hi = _face_cols(yr, f, ny, nx)
        for i in range(max(i0, lo), min(i1, hi)):
            af = a[f, i]
            if af <= 0.0:
                continue
            ar = a[f + 1, i]
            if ar < 0.0:
                cap = rho_max - rho[f, i]
                total = af - ar
                if cap < 0.0:
                    cap = 0.0
                if total > cap:
                    s = cap / total
                    a[f, i] = af * s
                    a[f + 1, i] = ar * s
            else:
                cap = rho_max - rho[f, i] + ar
                if cap < 0.0:
                    cap = 0.0
                if af > cap:
                    a[f, i] = cap
    if not has_negative:
        return
    for f in range(j0 + 1, ny + 1):
        lo, hi = _face_cols(yr, f, ny, nx)
        for i in range(max(i0, lo), min(i1, hi)):
            af = a[f, i]
            if af >= 0.0:
                continue
            al = a[f - 1, i]
            if al > 0.0:
                continue
            cap = rho_max - rho[f - 1, i] - al
            if cap < 0.0:
                cap = 0.0
            if -af > cap:
                a[f, i] = -cap
