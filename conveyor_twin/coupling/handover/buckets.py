"""Buckets: the micro parts near a release spot, found without a pass over all parts."""

from numba import njit
import numpy as np

from conveyor_twin.micro.state import P_X, P_Y

# Bucket edge over the largest search reach of a release (keeps round-off off the edge).
BUCKET_SLACK = 1.01
# Buckets of the micro-part lookup per macro grid (the edge grows when more would be needed).
BUCKETS = 1 << 14


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
