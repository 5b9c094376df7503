"""Static geometry: obstacles compiled to rounded convex shapes, and the uniform grids.

``wall`` and ``deflector`` polylines become one capsule per segment (radius thickness/2), a
``peg`` a one-vertex shape of its radius, a ``polygon`` its convex core (radius 0, made counter-
clockwise). The grid covers the cell with cells of size ``h >= 2 * largest bounding radius +
margin``, so two parts can only touch if their centre cells are neighbours; every static shape
is listed in each cell its bounding box, grown by the largest part radius and the margin,
covers. Positions outside the grid clamp to its border cells (still exact, just slower).
"""

from dataclasses import dataclass
import math
from typing import List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell, Obstacle, ObstacleKind
from conveyor_twin.micro.contacts.tables import (SH_AX, SH_AY, SH_BX, SH_BY, SH_COLUMNS, SH_E,
                                                 SH_MU, SH_NV, SH_OFF, SH_R, SH_XMAX, SH_XMIN,
                                                 SH_YMAX, SH_YMIN)

# Most grid cells allowed; the cell size grows to stay below it.
MAX_GRID_CELLS = 1 << 20


def obstacle_shapes(obstacles: Sequence[Obstacle]) -> Tuple[np.ndarray, np.ndarray, List[int]]:
    """Return (shape table (S, SH_COLUMNS), core vertices (V, 2) [m], obstacle index per shape)."""
    rows: List[np.ndarray] = []
    verts: List[Tuple[float, float]] = []
    owner: List[int] = []

    def add(points: Sequence[Tuple[float, float]], radius: float, obstacle: Obstacle,
            index: int) -> None:
        row = np.zeros(SH_COLUMNS)
        row[SH_NV] = len(points)
        row[SH_OFF] = len(verts)
        row[SH_R] = radius
        row[SH_E] = obstacle.restitution
        row[SH_MU] = obstacle.friction
        xs = [p[0] for p in points]
        ys = [p[1] for p in points]
        row[SH_XMIN] = min(xs) - radius
        row[SH_YMIN] = min(ys) - radius
        row[SH_XMAX] = max(xs) + radius
        row[SH_YMAX] = max(ys) + radius
        row[SH_AX], row[SH_AY] = points[0]
        row[SH_BX], row[SH_BY] = points[min(1, len(points) - 1)]
        rows.append(row)
        verts.extend((float(p[0]), float(p[1])) for p in points)
        owner.append(index)

    for index, obstacle in enumerate(obstacles):
        if obstacle.kind in (ObstacleKind.WALL, ObstacleKind.DEFLECTOR):
            pts = obstacle.points
            for a, b in zip(pts[:-1], pts[1:]):
                add((a, b), 0.5 * obstacle.thickness, obstacle, index)
        elif obstacle.kind == ObstacleKind.PEG:
            add((obstacle.points[0],), obstacle.radius, obstacle, index)
        else:
            pts = list(obstacle.points)
            area = sum(p[0] * q[1] - q[0] * p[1] for p, q in zip(pts, pts[1:] + pts[:1]))
            if area < 0.0:
                pts.reverse()
            add(pts, 0.0, obstacle, index)
    table = np.array(rows, dtype=np.float64).reshape(len(rows), SH_COLUMNS)
    return table, np.array(verts, dtype=np.float64).reshape(len(verts), 2), owner


@dataclass
class Grid:
    """A uniform grid over the cell and the static shapes of each of its cells.

    :param gpar: (x0, y0, h) origin and cell size [m]. :param gdim: (nx, ny).
    """

    gpar: np.ndarray
    gdim: np.ndarray
    static_start: np.ndarray
    static_items: np.ndarray

    @property
    def cells(self) -> int:
        """Number of grid cells."""
        return int(self.gdim[0] * self.gdim[1])


def world_bounds(cell: Cell, shapes: np.ndarray,
                 region: Optional[Tuple[float, float, float, float]]) -> Tuple[float, ...]:
    """Return (x_min, y_min, x_max, y_max) of everything parts can reach in the cell [m]."""
    xs: List[float] = []
    ys: List[float] = []
    for belt in cell.belts:
        if belt.curve is not None:
            x0, y0, x1, y1 = belt.bounding_box()
            xs += [x0, x1]
            ys += [y0, y1]
            continue
        for c in belt.corners():
            xs.append(c[0])
            ys.append(c[1])
    for rect in [s.region for s in cell.sources] + [s.region for s in cell.sinks] + (
            [region] if region else []):
        xs += [rect[0], rect[2]]
        ys += [rect[1], rect[3]]
    if shapes.shape[0]:
        xs += list(shapes[:, SH_XMIN]) + list(shapes[:, SH_XMAX])
        ys += list(shapes[:, SH_YMIN]) + list(shapes[:, SH_YMAX])
    for act in cell.actuators:
        reach = act.length + act.width + abs(act.position_range[1]) + abs(
            act.position_range[0])
        xs += [act.base[0] - reach, act.base[0] + reach]
        ys += [act.base[1] - reach, act.base[1] + reach]
    if not xs:
        return (-1.0, -1.0, 1.0, 1.0)
    return (min(xs), min(ys), max(xs), max(ys))


def cell_extent(cell: Cell, shapes: np.ndarray) -> Tuple[float, float, float, float]:
    """Return (x_min, y_min, x_max, y_max) of the cell [m]: everything parts can reach (belts,
    sources, sinks, obstacles, actuators' reach) and its zones."""
    x0, y0, x1, y1 = world_bounds(cell, shapes, None)
    for zone in cell.zones:
        x0, y0 = min(x0, zone.region[0]), min(y0, zone.region[1])
        x1, y1 = max(x1, zone.region[2]), max(y1, zone.region[3])
    return (x0, y0, x1, y1)


def outside_extent(extent: Tuple[float, float, float, float], x: np.ndarray,
                   y: np.ndarray) -> np.ndarray:
    """Return the indices of the points (x, y) [m] outside ``extent`` (non-finite ones too)."""
    x0, y0, x1, y1 = extent
    inside = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    return np.flatnonzero(~inside)


def _segment_distance(px: float, py: float, ax: float, ay: float, bx: float,
                      by: float) -> float:
    """Return the distance from point p to the segment a-b [m]."""
    ex = bx - ax
    ey = by - ay
    l2 = ex * ex + ey * ey
    f = 0.0
    if l2 > 0.0:
        f = min(max(((px - ax) * ex + (py - ay) * ey) / l2, 0.0), 1.0)
    return math.hypot(px - (ax + f * ex), py - (ay + f * ey))


def build_grid(bounds: Sequence[float], max_brad: float, margin: float, shapes: np.ndarray,
               min_h: float = 0.0) -> Grid:
    """Return the grid over ``bounds`` for parts up to ``max_brad`` [m] with ``margin`` [m]."""
    h = max(2.0 * max_brad + margin, min_h)
    x0 = bounds[0] - 2.0 * h
    y0 = bounds[1] - 2.0 * h
    width = bounds[2] - bounds[0] + 4.0 * h
    height = bounds[3] - bounds[1] + 4.0 * h
    while math.ceil(width / h) * math.ceil(height / h) > MAX_GRID_CELLS:
        h *= 1.25
    nx = max(1, int(math.ceil(width / h)))
    ny = max(1, int(math.ceil(height / h)))
    lists: List[List[int]] = [[] for _ in range(nx * ny)]
    grow = max_brad + margin
    # a part centred in a cell is at most half a diagonal from the cell's centre
    half_diagonal = h * math.sqrt(0.5) * (1.0 + 1e-9) + 1e-12
    for s in range(shapes.shape[0]):
        cx0 = min(max(int(math.floor((shapes[s, SH_XMIN] - grow - x0) / h)), 0), nx - 1)
        cx1 = min(max(int(math.floor((shapes[s, SH_XMAX] + grow - x0) / h)), 0), nx - 1)
        cy0 = min(max(int(math.floor((shapes[s, SH_YMIN] - grow - y0) / h)), 0), ny - 1)
        cy1 = min(max(int(math.floor((shapes[s, SH_YMAX] + grow - y0) / h)), 0), ny - 1)
        # segments and pegs: only the cells whose parts can reach the core (a long oblique
        # deflector's bounding box holds many cells no part in which can touch it); border
        # cells (parts outside the grid are clamped into them) keep the bounding-box rule
        reach = shapes[s, SH_R] + grow + half_diagonal
        segment = shapes[s, SH_NV] <= 2
        ax, ay, bx, by = (shapes[s, SH_AX], shapes[s, SH_AY], shapes[s, SH_BX],
                          shapes[s, SH_BY])
        for cy in range(cy0, cy1 + 1):
            for cx in range(cx0, cx1 + 1):
                if (segment and 0 < cx < nx - 1 and 0 < cy < ny - 1
                        and _segment_distance(x0 + (cx + 0.5) * h, y0 + (cy + 0.5) * h,
                                              ax, ay, bx, by) > reach):
                    continue
                lists[cy * nx + cx].append(s)
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    start[1:] = np.cumsum([len(cell) for cell in lists])
    items = np.array([s for cell in lists for s in cell], dtype=np.int64)
    return Grid(np.array([x0, y0, h], dtype=np.float64), np.array([nx, ny], dtype=np.int64),
                start, items)
