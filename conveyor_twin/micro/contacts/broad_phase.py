"""Broad phase: which parts may touch (uniform grid, neighbour list with a skin).

The broad phase is a neighbour list with a skin (:func:`update_pairs`), searched on a uniform
grid (:func:`build_grid`) only when a part moved more than half the skin or parts came or went;
it gives exactly the contacts of a fresh search, so results do not depend on when it was
rebuilt. Pairs are listed in canonical order (i, then j ascending, i < j).
"""

import math

from numba import njit
import numpy as np

from conveyor_twin.micro.contacts.tables import CONTACTS_PER_PART
from conveyor_twin.micro.state import PT_BRAD


@njit(cache=True)
def build_grid(n, x, y, gpar, gdim, cell_table, cell_items, part_cell):
    """Bin parts 0..n-1 by centre into the uniform grid: each cell's parts contiguous, ascending.

    Costs O(n), not O(cells): a cell's entries are valid only if its mark is this call's stamp,
    so no pass over the whole grid clears it (a long belt has ~10^5-10^6 cells). Two passes over
    the parts: count per cell, then place each part at its cell's cursor (a cell's range starts
    when its first part is placed), so the near phase reads every cell as one contiguous run.

    :param gpar: (x0, y0, h): grid origin and cell size [m]. :param gdim: (nx, ny).
    :param cell_table: int64[3*cells + 1], updated: ``[0, cells)`` where each cell's run starts
        in ``cell_items``, ``[cells, 2*cells)`` where it ends, ``[2*cells, 3*cells)`` the stamp
        of the call that wrote it, ``[3*cells]`` the current stamp. ``cell_items``
        int64[capacity] (output): the parts, grouped by cell; ``part_cell`` int64[capacity]
        (output): cell of each part.
    """
    x0 = gpar[0]
    y0 = gpar[1]
    inv_h = 1.0 / gpar[2]
    gnx = gdim[0]
    gny = gdim[1]
    ncell = gnx * gny
    mark = 2 * ncell
    stamp = cell_table[3 * ncell] + 1
    cell_table[3 * ncell] = stamp
    for i in range(n):
        cx = int(math.floor((x[i] - x0) * inv_h)) if x[i] == x[i] else 0
        cy = int(math.floor((y[i] - y0) * inv_h)) if y[i] == y[i] else 0
        cx = min(max(cx, 0), gnx - 1)
        cy = min(max(cy, 0), gny - 1)
        c = cy * gnx + cx
        part_cell[i] = c
        if cell_table[mark + c] != stamp:
            cell_table[mark + c] = stamp
            cell_table[c] = -1              # run not placed yet
            cell_table[ncell + c] = 0       # count
        cell_table[ncell + c] += 1
    off = 0
    for i in range(n):
        c = part_cell[i]
        if cell_table[c] < 0:
            count = cell_table[ncell + c]
            cell_table[c] = off
            cell_table[ncell + c] = off
            off += count
        k = cell_table[ncell + c]
        cell_items[k] = i
        cell_table[ncell + c] = k + 1


def grid_table(cells: int) -> np.ndarray:
    """Return the ``cell_table`` of :func:`build_grid` for a grid of ``cells`` cells."""
    return np.zeros(3 * cells + 1, dtype=np.int64)


# --- neighbour list (``nbr``, int64): header, then the ids of the parts it was built for
# (capacity), the start of each part's run of partners (capacity + 1) and the partners ---
NB_VALID = 0          # 1: holds the pairs of the parts in ``nbr[NB_HEADER:]``
NB_N = 1              # parts when built
NB_PAIRS = 2          # pairs listed
NB_BUILDS = 3         # builds so far (statistics)
NB_HEADER = 4
# A part may move this fraction of the skin before the list is rebuilt (< 1/2: two parts
# approaching each other then close less than the skin; the rest absorbs rounding).
NB_MOVE = 0.49


def neighbour_arrays(capacity: int):
    """Return the arrays of :func:`update_pairs`: ``nbr`` (int64) and ``pos0`` (2, capacity)."""
    size = NB_HEADER + 2 * capacity + 1 + CONTACTS_PER_PART * capacity
    return np.zeros(size, dtype=np.int64), np.zeros((2, capacity))


@njit(cache=True)
def update_pairs(n, ids, ptype, x, y, pt, gpar, gdim, cell_table, cell_items, part_cell, cand,
                 nbr, pos0, skins):
    """Keep the candidate pairs of parts 0..n-1 current (a Verlet list with a ``skin`` [m]).

    The list holds every pair (i, j), i < j, whose centres were closer than the sum of their
    bounding radii plus ``skin`` plus ``reach`` (the narrow phase's largest speculative margin)
    when it was built, in canonical order (i, then j ascending),
    and the grid cell of each part then (``part_cell``, for the static shapes; the grid's cells
    and static lists are grown by the skin). It is kept while the same parts (ids, slots) are
    present and none has moved ``NB_MOVE * skin`` since; then no pair outside it can touch, and
    the contacts are exactly those of a fresh search. Otherwise the grid is built and the
    pairs searched again. In a jam the list lives for many steps; in free flow at a speed v it
    is rebuilt every ``NB_MOVE * skin / (v dt)`` steps.

    :param nbr: int64 list (see :func:`neighbour_arrays`), updated. :param pos0: (2, capacity)
        positions at the build [m], updated. :param skins: ``(skin, reach)`` [m]; the grid
        cell must be at least twice the largest bounding radius plus ``skin`` plus ``reach``.
    :return: 0 kept, 1 rebuilt, 2 rebuilt but full (pairs beyond the capacity are dropped and
        the next call rebuilds).
    """
    skin, reach = skins
    cap = pos0.shape[1]
    o_ids = NB_HEADER
    o_start = o_ids + cap
    o_j = o_start + cap + 1
    jcap = nbr.shape[0] - o_j
    if nbr[NB_VALID] == 1 and nbr[NB_N] == n:
        lim = (NB_MOVE * skin) ** 2
        keep = True
        for i in range(n):
            dx = x[i] - pos0[0, i]
            dy = y[i] - pos0[1, i]
            if nbr[o_ids + i] != ids[i] or not dx * dx + dy * dy < lim:
                keep = False
                break
        if keep:
            return 0
    build_grid(n, x, y, gpar, gdim, cell_table, cell_items, part_cell)
    nbr[NB_BUILDS] += 1
    gnx = gdim[0]
    gny = gdim[1]
    ncell = gnx * gny
    mark = 2 * ncell
    stamp = cell_table[3 * ncell]
    npairs = 0
    full = False
    for i in range(n):
        nbr[o_ids + i] = ids[i]
        pos0[0, i] = x[i]
        pos0[1, i] = y[i]
        nbr[o_start + i] = npairs
        bri = pt[ptype[i], PT_BRAD] + skin + reach
        c = part_cell[i]
        cy = c // gnx
        cx = c - cy * gnx
        m = 0
        xi = x[i]
        yi = y[i]
        gx0 = max(cx - 1, 0)
        gx1 = min(cx + 1, gnx - 1)
        for gy in range(max(cy - 1, 0), min(cy + 2, gny)):
            row = gy * gnx
            for c9 in range(row + gx0, row + gx1 + 1):
                if cell_table[mark + c9] != stamp:
                    continue  # empty since the last build
                for k in range(cell_table[c9], cell_table[ncell + c9]):
                    j = cell_items[k]
                    dx = x[j] - xi
                    dy = y[j] - yi
                    rr = bri + pt[ptype[j], PT_BRAD]
                    if j > i and dx * dx + dy * dy < rr * rr:
                        # insertion sort by j: canonical order whatever order cells are read
                        p = m
                        while p > 0 and cand[p - 1] > j:
                            cand[p] = cand[p - 1]
                            p -= 1
                        cand[p] = j
                        m += 1
        if npairs + m > jcap:
            m = jcap - npairs
            full = True
        for p in range(m):
            nbr[o_j + npairs + p] = cand[p]
        npairs += m
    nbr[o_start + n] = npairs
    nbr[NB_N] = n
    nbr[NB_PAIRS] = npairs
    nbr[NB_VALID] = 0 if full else 1
    return 2 if full else 1
