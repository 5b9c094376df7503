"""Where a link takes parts out of a cell and puts them in, and the link frame between.

A link has a frame at each end: at the exit, origin at the sink's centre (or the belt's end)
and x along the belt that carries parts there (a curved belt: its tangent there); at the
entry, origin on the entry line (the belt's start, or the region's upstream edge) and x along
the belt that carries them on. A
part crossing keeps its lateral offset, yaw and velocity relative to these frames; its
longitudinal offset is replaced by the entry line (the link's delay is its travel time).
"""

import math
from typing import Tuple

import numpy as np
from numba import njit

from conveyor_twin.cell.model import Belt, Cell, Rect
from conveyor_twin.plant.model import EndFrame, LinkEnd

#: Depth of the exit behind a belt's end [m]: a part whose centre passed the end line leaves.
BELT_EXIT_DEPTH = 0.2
#: Gap between the entry line and a placed part's edge [m].
ENTRY_MARGIN = 0.001


def _nearest_belt(cell: Cell, x: float, y: float, at_end: bool) -> Belt:
    """Return the belt whose end (or start) is nearest to (x, y)."""
    def distance(b: Belt) -> float:
        px, py = b.end if at_end else b.start
        return math.hypot(px - x, py - y)
    return min(cell.belts, key=distance)


def heading(belt: Belt, *, at_end: bool) -> float:
    """Return the running direction [rad] of a belt at its end (or start): a straight belt's
    angle, a curved belt's tangent there (its angle plus or minus 90 degrees)."""
    if belt.curve is None:
        return belt.angle
    curve = belt.curve
    angle = curve.start_angle + curve.sweep if at_end else curve.start_angle
    return _wrap(angle + math.copysign(0.5 * math.pi, curve.sweep))


def end_rect(f: EndFrame) -> Rect:
    """Return the axis-aligned bounding rectangle of a link end's rectangle [m]."""
    c, s = math.cos(f.yaw), math.sin(f.yaw)
    xs, ys = [], []
    for u in (f.x0, f.x1):
        for v in (-f.half_width, f.half_width):
            xs.append(f.x + c * u - s * v)
            ys.append(f.y + s * u + c * v)
    return (min(xs), min(ys), max(xs), max(ys))


def end_frame(cell: Cell, end: LinkEnd, *, exit_side: bool) -> EndFrame:
    """Return the frame and rectangle of a link end (``exit_side``: it is a ``from``)."""
    if end.sink is not None:
        sink = next(s for s in cell.sinks if s.name == end.sink)
        return _rect_frame(cell, sink.region, at_end=True)
    if end.belt is not None:
        belt = cell.belts[cell.belt_index(end.belt)]
        half = 0.5 * belt.width
        if exit_side:
            ex, ey = belt.end
            return EndFrame(ex, ey, heading(belt, at_end=True), 0.0, BELT_EXIT_DEPTH, half)
        sx, sy = belt.start
        return EndFrame(sx, sy, heading(belt, at_end=False), 0.0,
                        min(BELT_EXIT_DEPTH, belt.length), half)
    return _rect_frame(cell, end.region, at_end=False)


def _rect_frame(cell: Cell, rect: Rect, *, at_end: bool) -> EndFrame:
    """The frame of an axis-aligned rectangle, x along the nearest belt rounded to a
    multiple of 90 degrees (so the rectangle is exact in it)."""
    x0, y0, x1, y1 = rect
    cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    belt = _nearest_belt(cell, cx, cy, at_end)
    quarter = round(heading(belt, at_end=at_end) / (0.5 * math.pi)) % 4
    yaw = quarter * 0.5 * math.pi
    hx, hy = 0.5 * (x1 - x0), 0.5 * (y1 - y0)
    along, across = (hx, hy) if quarter % 2 == 0 else (hy, hx)
    if at_end:
        return EndFrame(cx, cy, _wrap(yaw), -along, along, across)
    # entry: origin on the upstream edge, the rectangle ahead of it
    ox, oy = cx - math.cos(yaw) * along, cy - math.sin(yaw) * along
    return EndFrame(ox, oy, _wrap(yaw), 0.0, 2.0 * along, across)


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@njit(cache=True)
def mark_inside(ox, oy, c, s, x0, x1, half_width, x, y, n, room, mark):
    """Mark in ``mark[:n]`` the first ``room`` of the points (x, y) [m] inside a link end's
    rectangle (frame origin (ox, oy) [m], yaw with cosine ``c`` and sine ``s``; x in [x0, x1],
    |y| <= half_width [m]), in order; return how many were marked."""
    k = 0
    for i in range(n):
        dx = x[i] - ox
        dy = y[i] - oy
        u = c * dx + s * dy
        v = -s * dx + c * dy
        hit = k < room and x0 <= u <= x1 and abs(v) <= half_width
        mark[i] = hit
        if hit:
            k += 1
    return k


def to_link(f: EndFrame, x: np.ndarray, y: np.ndarray, yaw: np.ndarray, vx: np.ndarray,
            vy: np.ndarray) -> Tuple[np.ndarray, ...]:
    """Express cell-frame poses [m, rad] and velocities [m/s] in the exit's link frame.

    :return: (x, y, yaw, vx, vy) in the link frame [m, m, rad, m/s, m/s], each array of the
        shape of the inputs.
    """
    c, s = math.cos(f.yaw), math.sin(f.yaw)
    dx, dy = x - f.x, y - f.y
    return (c * dx + s * dy, -s * dx + c * dy, np.arctan2(np.sin(yaw - f.yaw),
                                                          np.cos(yaw - f.yaw)),
            c * vx + s * vy, -s * vx + c * vy)


def entry_pose(f: EndFrame, radius: float, y: float, yaw: float, vx: float,
               vy: float) -> Tuple[float, float, float, float, float]:
    """Return the cell-frame (x, y, yaw, vx, vy) of a part entering with link-relative lateral
    offset ``y`` [m], ``yaw`` [rad] and velocity (vx, vy) [m/s]; the offset is clipped so the
    part (bounding ``radius`` [m]) lies inside the entry."""
    room = max(0.0, f.half_width - radius)
    v = min(max(y, -room), room)
    u = f.x0 + radius + ENTRY_MARGIN
    c, s = math.cos(f.yaw), math.sin(f.yaw)
    a = yaw + f.yaw
    return (f.x + c * u - s * v, f.y + s * u + c * v, math.atan2(math.sin(a), math.cos(a)),
            c * vx - s * vy, s * vx + c * vy)
