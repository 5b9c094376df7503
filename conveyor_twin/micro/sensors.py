"""Light barriers: per-step blocked state and edge events with interpolated times.

A beam (segment ``a``-``b`` at height ``h``) is blocked while the footprint of any part taller
than ``h`` intersects it (discs: centre closer than the radius; boxes: the segment crosses the
rectangle). Each step the state is sampled at the step's end; when it differs from the last
one an edge event is written with the fraction of the step at which it happened, found by
bisection on the pose interpolated linearly between the step's start and end (better than
1e-9 of a step), and the id of the part that caused it: the first part to enter for a rising
edge, the last to leave for a falling one. At most one edge per barrier and step is seen
(a part shorter than the step's travel can slip through unseen only if it is thinner than one
step's travel; 1 ms at 2 m/s is 2 mm).
"""

import math
from typing import Sequence

from numba import njit
import numpy as np

from conveyor_twin.cell.model import LightBarrier
from conveyor_twin.micro.state import (C_EVENTS, C_EVENTS_DROPPED, PT_BRAD, PT_HEIGHT, PT_HL,
                                       PT_HW, PT_RADIUS, PT_SHAPE, SHAPE_DISC)

LB_AX = 0
LB_AY = 1
LB_BX = 2
LB_BY = 3
LB_HEIGHT = 4
LB_COLUMNS = 5

# --- event columns ---
EV_BARRIER = 0
EV_BLOCKED = 1
EV_PART = 2
EV_STEP = 3
EV_INT_COLUMNS = 4
EV_FRACTION = 0       # fraction of the step at which the edge happened, [0, 1]
EV_TIME = 1           # sim time of the edge [s]
EV_FLOAT_COLUMNS = 2

_BISECTIONS = 32


def barrier_table(barriers: Sequence[LightBarrier]) -> np.ndarray:
    """Return the (L, LB_COLUMNS) table of the light barriers."""
    table = np.zeros((len(barriers), LB_COLUMNS), dtype=np.float64)
    for i, b in enumerate(barriers):
        table[i] = (b.start[0], b.start[1], b.end[0], b.end[1], b.height)
    return table


@njit(cache=True)
def blocks(pt, t, px, py, yaw, lb, b):
    """Return True if a part of type t at pose (p [m], yaw [rad]) interrupts beam b."""
    if pt[t, PT_HEIGHT] <= lb[b, LB_HEIGHT]:
        return False
    ax = lb[b, LB_AX]
    ay = lb[b, LB_AY]
    bx = lb[b, LB_BX]
    by = lb[b, LB_BY]
    if pt[t, PT_SHAPE] == SHAPE_DISC:
        ex = bx - ax
        ey = by - ay
        f = ((px - ax) * ex + (py - ay) * ey) / (ex * ex + ey * ey)
        f = min(max(f, 0.0), 1.0)
        dx = px - (ax + f * ex)
        dy = py - (ay + f * ey)
        r = pt[t, PT_RADIUS]
        return dx * dx + dy * dy < r * r
    # box: the segment in body coordinates against [-hl, hl] x [-hw, hw] (slab clipping)
    c = math.cos(yaw)
    s = math.sin(yaw)
    x0 = c * (ax - px) + s * (ay - py)
    y0 = -s * (ax - px) + c * (ay - py)
    x1 = c * (bx - px) + s * (by - py)
    y1 = -s * (bx - px) + c * (by - py)
    lo = 0.0
    hi = 1.0
    for axis in range(2):
        p0 = x0 if axis == 0 else y0
        p1 = x1 if axis == 0 else y1
        half = pt[t, PT_HL] if axis == 0 else pt[t, PT_HW]
        d = p1 - p0
        if d == 0.0:
            if abs(p0) >= half:
                return False
        else:
            t0 = (-half - p0) / d
            t1 = (half - p0) / d
            if t0 > t1:
                t0, t1 = t1, t0
            lo = max(lo, t0)
            hi = min(hi, t1)
            if lo >= hi:
                return False
    return True


@njit(cache=True)
def _blocks_at(pt, t, x0, y0, yaw0, x1, y1, yaw1, f, lb, b):
    dyaw = yaw1 - yaw0
    if dyaw > math.pi:
        dyaw -= 2.0 * math.pi
    elif dyaw < -math.pi:
        dyaw += 2.0 * math.pi
    return blocks(pt, t, x0 + f * (x1 - x0), y0 + f * (y1 - y0), yaw0 + f * dyaw, lb, b)


@njit(cache=True)
def _edge_fraction(pt, t, x0, y0, yaw0, x1, y1, yaw1, lb, b):
    """Return the fraction in (0, 1] where the blocked state of one part flips."""
    start = _blocks_at(pt, t, x0, y0, yaw0, x1, y1, yaw1, 0.0, lb, b)
    lo = 0.0
    hi = 1.0
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        if _blocks_at(pt, t, x0, y0, yaw0, x1, y1, yaw1, mid, lb, b) == start:
            lo = mid
        else:
            hi = mid
    return hi


@njit(cache=True)
def _near(pt, t, px, py, lb, b):
    r = pt[t, PT_BRAD]
    return not (px + r < min(lb[b, LB_AX], lb[b, LB_BX])
                or px - r > max(lb[b, LB_AX], lb[b, LB_BX])
                or py + r < min(lb[b, LB_AY], lb[b, LB_BY])
                or py - r > max(lb[b, LB_AY], lb[b, LB_BY]))


@njit(cache=True)
def update_barriers(n, ids, ptype, P, pt, lb, blocked, edge_count, last_part, ev_i, ev_f,
                    counters, step, dt):
    """Sample every beam after step ``step`` and record its edges.

    :param P: part state (rows x, y, yaw, vx, vy, wz, x_prev, y_prev, yaw_prev).
    :param blocked: bool[L] state, updated. :param edge_count: uint32[L], incremented.
    :param last_part: uint32[L] id of the part of the last edge.
    :param ev_i: int64 (cap, EV_INT_COLUMNS) and ``ev_f`` float64 (cap, EV_FLOAT_COLUMNS):
        the events buffer, ``counters[C_EVENTS]`` entries used.
    :param step: index of the step just taken (the state is stamped ``step * dt``).
    """
    x = P[0]
    y = P[1]
    yaw = P[2]
    xp = P[6]
    yp = P[7]
    yawp = P[8]
    for b in range(lb.shape[0]):
        now = False
        for i in range(n):
            t = ptype[i]
            if _near(pt, t, x[i], y[i], lb, b) and blocks(pt, t, x[i], y[i], yaw[i], lb, b):
                now = True
                break
        if now == blocked[b]:
            continue
        part = 0
        if now:
            frac = 2.0
            for i in range(n):
                t = ptype[i]
                if not (_near(pt, t, x[i], y[i], lb, b)
                        and blocks(pt, t, x[i], y[i], yaw[i], lb, b)):
                    continue
                if blocks(pt, t, xp[i], yp[i], yawp[i], lb, b):
                    f = 0.0
                else:
                    f = _edge_fraction(pt, t, xp[i], yp[i], yawp[i], x[i], y[i], yaw[i], lb, b)
                if f < frac:
                    frac = f
                    part = ids[i]
        else:
            frac = -1.0
            for i in range(n):
                t = ptype[i]
                if not (_near(pt, t, xp[i], yp[i], lb, b)
                        and blocks(pt, t, xp[i], yp[i], yawp[i], lb, b)):
                    continue
                f = _edge_fraction(pt, t, xp[i], yp[i], yawp[i], x[i], y[i], yaw[i], lb, b)
                if f > frac:
                    frac = f
                    part = ids[i]
            if frac < 0.0:
                # the blocking part was removed at the end of the last step
                frac = 0.0
                part = last_part[b]
        blocked[b] = now
        edge_count[b] += 1
        last_part[b] = part
        k = counters[C_EVENTS]
        if k < ev_i.shape[0]:
            ev_i[k, EV_BARRIER] = b
            ev_i[k, EV_BLOCKED] = 1 if now else 0
            ev_i[k, EV_PART] = part
            ev_i[k, EV_STEP] = step
            ev_f[k, EV_FRACTION] = frac
            ev_f[k, EV_TIME] = ((step - 1) + frac) * dt
            counters[C_EVENTS] = k + 1
        else:
            counters[C_EVENTS_DROPPED] += 1
