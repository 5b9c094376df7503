"""Deposit: captured micro parts become exactly one part's worth of macro density each.

:func:`capture_mask` marks the micro parts whose centre lies in an active (macro) cell;
:func:`deposit_disc` adds one part's worth of mass over the footprint disc of a captured part,
restricted to active fluid cells (renormalised, so the amount is exact); :func:`deposit_push`
also appends the parts' types to the zone's FIFO (read back by the release).
"""

from numba import njit
import numpy as np

# Sub-samples per cell edge when the footprint disc is rasterised.
DEPOSIT_SAMPLES = 8
# Margin [m] of the test that skips cells apart from a footprint disc (far above round-off).
_DISC_MARGIN = 1e-9


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
def deposit_push(rho: np.ndarray, active: np.ndarray, solid: np.ndarray, ox: float, oy: float,
                 h: float, x: np.ndarray, y: np.ndarray, types: np.ndarray,
                 radius_of_type: np.ndarray, fifo: np.ndarray, fstate: np.ndarray,
                 by_type: np.ndarray) -> None:
    """Deposit the captured parts (:func:`deposit_disc` each, in order) and append their types
    to the FIFO.

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
