"""Outflow: density leaving the macro grid through its boundary faces and sink cells.

:func:`accumulate_faces` adds the boundary outflow of the faces that do not lead into a sink
to the zone's face accumulators (released as parts by :mod:`.release`), :func:`side_max` reads
their largest value per side, and :func:`take_mask` / :func:`take_cells` remove the mass of
sink cells.
"""

from numba import njit
import numpy as np


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
