"""Parts leaving: sinks, the simulated region's border (to the outbox) and explicit removal.

Removal compacts the arrays, keeping the remaining parts in their order (ids ascending), so the
published order is stable. A part whose centre is inside a sink (first in cell order) is
counted there and dropped. With a region, a part whose centre leaves it goes to the outbox
(for the coordinator to hand over to another scale); a full outbox keeps the part until drained.
"""

from numba import njit

from conveyor_twin.micro.state import C_N, C_OUTBOX, C_REGION_LEFT, P_ROWS, P_X, P_Y

# --- region array slots ---
RG_ACTIVE = 0
RG_X0 = 1
RG_Y0 = 2
RG_X1 = 3
RG_Y1 = 4
RG_SIZE = 5

# --- outbox float rows: x, y, yaw, vx, vy, wz ---
OB_ROWS = 6


@njit(cache=True)
def _move(src, dst, ids, ptype, P):
    ids[dst] = ids[src]
    ptype[dst] = ptype[src]
    for r in range(P_ROWS):
        P[r, dst] = P[r, src]


@njit(cache=True)
def leave(counters, ids, ptype, P, sinks, sink_count, region, ob_id, ob_type, ob_P):
    """Remove parts in sinks (counted) and outside the region (to the outbox); compact.

    :param sinks: (K, 4) rectangles (x_min, y_min, x_max, y_max) [m].
    :param sink_count: int64[K] parts that left through each sink.
    :param region: float64[RG_SIZE]; ``ob_*``: the outbox, ``counters[C_OUTBOX]`` entries.
    """
    n = counters[C_N]
    k = 0
    for i in range(n):
        px = P[P_X, i]
        py = P[P_Y, i]
        gone = False
        for s in range(sinks.shape[0]):
            if sinks[s, 0] <= px <= sinks[s, 2] and sinks[s, 1] <= py <= sinks[s, 3]:
                sink_count[s] += 1
                gone = True
                break
        if not gone and region[RG_ACTIVE] != 0.0 and not (
                region[RG_X0] <= px <= region[RG_X1] and region[RG_Y0] <= py <= region[RG_Y1]):
            m = counters[C_OUTBOX]
            if m < ob_id.size:
                ob_id[m] = ids[i]
                ob_type[m] = ptype[i]
                for r in range(OB_ROWS):
                    ob_P[r, m] = P[r, i]
                counters[C_OUTBOX] = m + 1
                counters[C_REGION_LEFT] += 1
                gone = True
        if not gone:
            if k != i:
                _move(i, k, ids, ptype, P)
            k += 1
    counters[C_N] = k


@njit(cache=True)
def remove_marked(counters, ids, ptype, P, mark, out_id, out_type, out_P):
    """Remove the parts with ``mark[i]`` set, copying them to ``out_*`` in order; compact.

    :return: number of parts removed.
    """
    n = counters[C_N]
    k = 0
    m = 0
    for i in range(n):
        if mark[i]:
            out_id[m] = ids[i]
            out_type[m] = ptype[i]
            for r in range(OB_ROWS):
                out_P[r, m] = P[r, i]
            m += 1
        else:
            if k != i:
                _move(i, k, ids, ptype, P)
            k += 1
    counters[C_N] = k
    return m
