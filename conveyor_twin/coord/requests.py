"""What a ``spawn_parts`` or a ``reset`` request may contain (no ROS imports).

The coordinator node only converts the service request into these calls and answers with the
result: a :class:`RequestRejected` names what is wrong and is answered as ``success = false``
with its text; nothing is applied.
"""

from dataclasses import dataclass
import math
from typing import Optional, Sequence

import numpy as np

from conveyor_twin.cell import CellError, load_cell
from conveyor_twin.cell.model import Belt, Cell, Obstacle, ObstacleKind


class RequestRejected(ValueError):
    """A spawn or reset request the twin does not apply; the text says why."""


@dataclass(frozen=True)
class SpawnRequest:
    """A checked ``spawn_parts`` request: parts of one type at finite poses.

    :param part_type: name of the part type.
    :param type_index: its wire index in the cell.
    :param x: x of every part [m]. :param y: y [m]. :param yaw: yaw [rad].
    """

    part_type: str
    type_index: int
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray

    @property
    def count(self) -> int:
        """Number of parts requested."""
        return int(self.x.size)

    def placed_message(self) -> str:
        """Return the answer of a spawn that placed every part."""
        return f'placed {self.count} {self.part_type} part(s)'


def check_spawn(cell: Cell, part_type: str, x: Sequence[float], y: Sequence[float],
                yaw: Sequence[float]) -> SpawnRequest:
    """Check a spawn request against ``cell``.

    :param part_type: name of a part type of the cell.
    :param x: x of every part [m]. :param y: y of every part [m].
    :param yaw: yaw of every part [rad]; empty: 0 for every part.
    :raises RequestRejected: for an unknown part type, arrays of different or zero length, a
        pose that is not a finite number, or a part whose centre is not on a belt's surface
        or whose footprint (its bounding circle) overlaps a static obstacle (a wall, a
        deflector, a peg, a polygon); the message names the part (its index in the request),
        its position and the region allowed.
    """
    n = len(x)
    try:
        type_index = cell.part_type_index(part_type)
    except KeyError:
        raise RequestRejected(f'unknown part_type {part_type!r} (known: '
                              + ', '.join(p.name for p in cell.part_types) + ')') from None
    xs, ys = np.asarray(x, float), np.asarray(y, float)
    yaws = np.asarray(yaw, float) if len(yaw) else np.zeros(n)
    if not (len(y) == n and len(yaws) == n) or n == 0:
        raise RequestRejected(f'x, y and yaw must have the same non-zero length '
                              f'(got {n}, {len(y)}, {len(yaw)})')
    if not (np.isfinite(xs).all() and np.isfinite(ys).all() and np.isfinite(yaws).all()):
        raise RequestRejected('poses must be finite numbers')
    radius = cell.part_types[type_index].bounding_radius
    for k in range(n):
        problem = placement_problem(cell, float(xs[k]), float(ys[k]), radius)
        if problem:
            raise RequestRejected(f'part {k} ({part_type}) at x = {xs[k]:g} m, y = {ys[k]:g} m '
                                  f'{problem}; nothing placed')
    return SpawnRequest(part_type, type_index, xs, ys, yaws)


def belt_region(belt: Belt) -> str:
    """Describe the surface of a belt (where a spawned part's centre may lie)."""
    (x0, y0), (x1, y1) = belt.start, belt.end
    if belt.curve is not None:
        c = belt.curve
        return (f'belt {belt.name!r}: radius {c.inner_radius:g}..{c.outer_radius:g} m about '
                f'({c.centre[0]:g}, {c.centre[1]:g}) from {math.degrees(c.start_angle):g} deg '
                f'through {math.degrees(c.sweep):g} deg')
    if y0 == y1 and x0 <= x1:
        return (f'belt {belt.name!r}: x {x0:g}..{x1:g} m, y {y0 - belt.width / 2:g}..'
                f'{y0 + belt.width / 2:g} m')
    return (f'belt {belt.name!r}: {belt.width:g} m wide along ({x0:g}, {y0:g})-'
            f'({x1:g}, {y1:g}) m')


def on_belt(belt: Belt, x: float, y: float) -> bool:
    """True if (x, y) [m] lies on the surface of ``belt`` (edges included, within 1e-9 m)."""
    return belt.contains((x, y))


def placement_problem(cell: Cell, x: float, y: float, radius: float) -> str:
    """Return why a part of bounding ``radius`` [m] cannot be spawned at (x, y) [m] on
    ``cell`` ('' if it can): its centre must lie on a belt's surface, its bounding circle must
    not overlap a static obstacle."""
    if not any(on_belt(b, x, y) for b in cell.belts):
        regions = '; '.join(belt_region(b) for b in cell.belts)
        return f'is not on a belt (allowed: a centre on {regions})'
    for obstacle in cell.obstacles:
        gap = _clearance(obstacle, x, y)
        if gap is not None and gap < radius:
            return (f'overlaps {obstacle.kind.value} {obstacle.name!r} (its footprint reaches '
                    f'{radius:g} m from the centre, the obstacle is {max(gap, 0.0):g} m away; '
                    'allowed: on a belt, clear of every wall, deflector, peg and polygon)')
    return ''


def _segment_distance(px: float, py: float, a: Sequence[float], b: Sequence[float]) -> float:
    ax, ay = a
    bx, by = b
    vx, vy = bx - ax, by - ay
    length2 = vx * vx + vy * vy
    t = 0.0 if length2 == 0.0 else min(1.0, max(0.0, ((px - ax) * vx + (py - ay) * vy)
                                                / length2))
    return math.hypot(px - (ax + t * vx), py - (ay + t * vy))


def _clearance(obstacle: Obstacle, x: float, y: float) -> Optional[float]:
    """Distance [m] from (x, y) to the surface of ``obstacle`` (negative or 0 inside)."""
    points = obstacle.points
    if obstacle.kind in (ObstacleKind.WALL, ObstacleKind.DEFLECTOR):
        return min(_segment_distance(x, y, points[i], points[i + 1])
                   for i in range(len(points) - 1)) - obstacle.thickness / 2
    if obstacle.kind == ObstacleKind.PEG:
        return math.hypot(x - points[0][0], y - points[0][1]) - obstacle.radius
    if obstacle.kind == ObstacleKind.POLYGON:
        edges = [(points[i], points[(i + 1) % len(points)]) for i in range(len(points))]
        inside = all((b[0] - a[0]) * (y - a[1]) - (b[1] - a[1]) * (x - a[0]) >= 0.0
                     for a, b in edges)
        distance = min(_segment_distance(x, y, a, b) for a, b in edges)
        return -distance if inside else distance
    return None


def same_interface(a: Cell, b: Cell) -> bool:
    """Return True if ``a`` and ``b`` publish the same arrays: the same belts, actuators, light
    barriers and zones, by name and in order."""
    def names(cell: Cell):
        return ([x.name for x in cell.belts], [x.name for x in cell.actuators],
                [x.name for x in cell.light_barriers], [z.name for z in cell.zones])
    return names(a) == names(b)


def check_reset(current: Cell, cell_file: str) -> Cell:
    """Return the cell a reset request restarts with.

    :param current: the cell running now.
    :param cell_file: another cell YAML; empty: ``current``.
    :raises RequestRejected: if the file is not a valid cell (the loader's message naming file,
        key and value), or its belts, actuators, light barriers or zones differ from
        ``current``'s (the published arrays would change).
    """
    try:
        cell = load_cell(cell_file) if cell_file else current
    except CellError as exc:
        raise RequestRejected(str(exc)) from None
    if cell is not current and not same_interface(cell, current):
        raise RequestRejected('reset to a cell with other belts, actuators or light barriers '
                              'needs a restart of the twin (the published arrays would change)')
    return cell


def reset_message(seed: int, cell: Cell) -> str:
    """Return the answer of a reset that restarted with ``seed`` and ``cell``."""
    return f'reset to step 0 with seed {seed} ({cell.settings.name})'
