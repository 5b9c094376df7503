"""Draw a cell's layout to scale on matplotlib axes, every element named.

Belts are grey surfaces with an arrow along their running direction (a curved belt: its
annular sector, the arrow bent along its centre line); walls and deflectors (and a curve's
guide rails) are drawn at their real thickness, pegs and polygons as their outline; actuators
at their initial position with their stroke (the swept area, dashed), transfer units as their
roller footprint, coloured up or down; light barriers as beams; sources, sinks and zones as
labelled regions (a zone's label gives its scale policy). Units: m, frame of the cell (x along
the main conveying direction, y to the left).
"""

import math
from typing import List, Sequence, Tuple

from conveyor_twin.cell.model import Actuator, Belt, Cell, Obstacle
from conveyor_twin.viz.label_placement import add_label, place_labels

BELT_FACE = '#d9d9d9'
BELT_EDGE = '#6e6e6e'
OBSTACLE_FACE = '#4a5a6a'
ACTUATOR_FACE = '#e8b400'
#: Transfer unit lowered (the belt carries) and raised to its engage height (it carries).
TRANSFER_DOWN = '#9ec9e8'
TRANSFER_UP = '#1f6fb4'
#: Largest distance [m] between a drawn curve and the true arc.
CHORD_ERROR = 1e-4
BEAM_FREE = '#1a9e1a'
BEAM_BLOCKED = '#e0201a'
SOURCE_COLOUR = '#2a7fd4'
SINK_COLOUR = '#c0392b'
ZONE_COLOURS = {'micro': '#7b3fa0', 'macro': '#d35400', 'auto': '#16a085'}
LABEL_SIZE = 7


def segment_outline(a: Tuple[float, float], b: Tuple[float, float],
                    thickness: float) -> List[Tuple[float, float]]:
    """Return the 4 corners of a segment of full ``thickness`` [m] (counter-clockwise)."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    length = math.hypot(dx, dy) or 1.0
    nx, ny = -dy / length * thickness / 2, dx / length * thickness / 2
    return [(a[0] - nx, a[1] - ny), (b[0] - nx, b[1] - ny), (b[0] + nx, b[1] + ny),
            (a[0] + nx, a[1] + ny)]


def actuator_outline(act: Actuator, position: float) -> List[Tuple[float, float]]:
    """Return the footprint corners of an actuator at ``position`` [m or rad].

    A pusher's paddle is centred at ``base + position * axis`` (``length`` along the axis); a
    stopper's blade is centred at ``base``; a diverter's arm runs from the pivot along the axis
    turned by ``position``.
    """
    ax, ay = act.axis
    if act.kind == 'diverter':
        angle = math.atan2(ay, ax) + position
        tip = (act.base[0] + act.length * math.cos(angle),
               act.base[1] + act.length * math.sin(angle))
        return segment_outline(act.base, tip, act.width)
    if act.kind == 'pusher':
        cx, cy = act.base[0] + position * ax, act.base[1] + position * ay
    else:
        cx, cy = act.base
    half = 0.5 * act.length
    return segment_outline((cx - half * ax, cy - half * ay), (cx + half * ax, cy + half * ay),
                           act.width)


def _rect(region: Sequence[float]) -> Tuple[Tuple[float, float], float, float]:
    x0, y0, x1, y1 = region
    return (x0, y0), x1 - x0, y1 - y0


def _label(ax, x: float, y: float, text: str, colour: str, *, dy: float = 0.0,
           dx: float = 0.0) -> None:
    """Name the point (x, y) [m]; (dx, dy) is the preferred side, placed by ``place_labels``."""
    add_label(ax, x, y, text, colour, direction=(dx, dy or -1.0), fontsize=LABEL_SIZE)


def draw_static(ax, cell: Cell, *, labels: bool = True) -> None:
    """Draw belts, obstacles, sources, sinks and zones (what never moves) on ``ax``."""
    from matplotlib.patches import Circle, FancyArrow, Polygon, Rectangle

    for belt in cell.belts:
        if belt.curve is not None:
            _draw_curved_belt(ax, belt, labels, Polygon)
            continue
        ax.add_patch(Polygon(belt.corners(), closed=True, fc=BELT_FACE, ec=BELT_EDGE, lw=0.8,
                             zorder=0))
        dx, dy = belt.direction
        arrow = min(0.25 * belt.length, 3 * belt.width)
        cx = belt.start[0] + 0.12 * belt.length * dx
        cy = belt.start[1] + 0.12 * belt.length * dy
        ax.add_patch(FancyArrow(cx, cy, arrow * dx, arrow * dy, width=0.12 * belt.width,
                                head_width=0.3 * belt.width, head_length=0.25 * belt.width,
                                length_includes_head=True, fc=BELT_EDGE, ec='none',
                                alpha=0.6, zorder=1))
        if labels:
            _label(ax, cx + 0.5 * arrow * dx, cy + 0.5 * arrow * dy,
                   f'belt {belt.name} ({belt.speed:g} m/s)', '#333333', dy=-1.0)
    for zone in cell.zones:
        colour = ZONE_COLOURS.get(zone.policy, 'black')
        xy, w, h = _rect(zone.region)
        ax.add_patch(Rectangle(xy, w, h, fill=False, ec=colour, lw=1.0, ls=(0, (6, 3)),
                               zorder=2))
        if labels:
            _label(ax, zone.region[0], zone.region[1],
                   f'zone {zone.name}: {zone.policy} ({zone.resolution * 1e3:g} mm grid)',
                   colour, dx=1.0, dy=1.0)
    for source in cell.sources:
        xy, w, h = _rect(source.region)
        ax.add_patch(Rectangle(xy, w, h, fc=SOURCE_COLOUR, ec=SOURCE_COLOUR, alpha=0.3,
                               hatch='//', zorder=2))
        if labels:
            _label(ax, xy[0] + 0.5 * w, source.region[1],
                   f'source {source.name}: {source.rate:g}/s {source.part_type}',
                   SOURCE_COLOUR, dy=-1.0)
    for sink in cell.sinks:
        xy, w, h = _rect(sink.region)
        ax.add_patch(Rectangle(xy, w, h, fc=SINK_COLOUR, ec=SINK_COLOUR, alpha=0.25,
                               hatch='xx', zorder=2))
        if labels:
            _label(ax, xy[0] + 0.5 * w, sink.region[1], f'sink {sink.name}', SINK_COLOUR,
                   dy=-1.0)
    mid_y = 0.5 * (view_limits(cell)[2] + view_limits(cell)[3]) if cell.obstacles else 0.0
    for obstacle in cell.obstacles:
        for patch in _obstacle_patches(obstacle, Circle, Polygon):
            ax.add_patch(patch)
        if labels:
            x, y = _obstacle_anchor(obstacle)
            _label(ax, x, y, obstacle.name, OBSTACLE_FACE, dy=1.0 if y >= mid_y else -1.0)


def _draw_curved_belt(ax, belt: Belt, labels: bool, Polygon) -> None:
    """Draw a curved belt: its annular sector and the arrow along its centre line."""
    ax.add_patch(Polygon(belt.outline(CHORD_ERROR), closed=True, fc=BELT_FACE, ec=BELT_EDGE,
                         lw=0.8, zorder=0))
    arrow, (x, y) = curve_arrow(belt)
    ax.add_patch(Polygon(arrow, closed=True, fc=BELT_EDGE, ec='none', alpha=0.6, zorder=1))
    if labels:
        _label(ax, x, y, f'belt {belt.name} ({belt.speed:g} m/s)', '#333333', dy=-1.0)


def curve_arrow(belt: Belt) -> Tuple[List[Tuple[float, float]], Tuple[float, float]]:
    """Return a curved belt's running-direction arrow and the point its label names [m].

    The arrow is a band along the centre line (from 12 % of the length, as long as a
    straight belt's arrow: at most a quarter of the length or three widths) ending in a head
    whose tip lies on the centre line; drawn within :data:`CHORD_ERROR` of the arcs.
    """
    curve = belt.curve
    r, w = curve.centre_radius, belt.width
    sign = 1.0 if curve.sweep > 0 else -1.0
    arrow = min(0.25 * belt.length, 3 * w)
    head = min(0.25 * w, 0.5 * arrow)
    s0 = 0.12 * belt.length
    s1, tip = s0 + arrow - head, s0 + arrow
    shaft, spread = 0.06 * w, 0.15 * w
    cx, cy = curve.centre

    def at(s: float, offset: float) -> Tuple[float, float]:
        theta = curve.start_angle + sign * s / r
        return cx + (r + offset) * math.cos(theta), cy + (r + offset) * math.sin(theta)

    step = 2.0 * math.acos(max(-1.0, 1.0 - CHORD_ERROR / (r + shaft)))
    n = max(2, math.ceil((s1 - s0) / r / step))
    along = [s0 + (s1 - s0) * k / n for k in range(n + 1)]
    points = ([at(s, shaft) for s in along] + [at(s1, spread), at(tip, 0.0), at(s1, -spread)]
              + [at(s, -shaft) for s in reversed(along)])
    return points, at(s0 + 0.5 * arrow, 0.0)


def _obstacle_patches(obstacle: Obstacle, Circle, Polygon) -> list:
    style = dict(fc=OBSTACLE_FACE, ec=OBSTACLE_FACE, lw=0.5, zorder=4)
    if obstacle.kind == 'peg':
        return [Circle(obstacle.points[0], obstacle.radius, **style)]
    if obstacle.kind == 'polygon':
        return [Polygon(obstacle.points, closed=True, **style)]
    thickness = obstacle.thickness if obstacle.thickness > 0 else 0.002
    return [Polygon(segment_outline(a, b, thickness), closed=True, **style)
            for a, b in zip(obstacle.points[:-1], obstacle.points[1:])]


def _obstacle_anchor(obstacle: Obstacle) -> Tuple[float, float]:
    """The point an obstacle's label names: the middle of a polyline of more than two points
    (along its length: on a curve's guide rail), else the mean of its points."""
    if obstacle.kind in ('wall', 'deflector') and len(obstacle.points) > 2:
        return _polyline_middle(obstacle.points)
    xs = [p[0] for p in obstacle.points]
    ys = [p[1] for p in obstacle.points]
    return sum(xs) / len(xs), sum(ys) / len(ys)


def _polyline_middle(points: Sequence[Tuple[float, float]]) -> Tuple[float, float]:
    """Return the point halfway along a polyline [m]."""
    lengths = [math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(points[:-1], points[1:])]
    left = 0.5 * sum(lengths)
    for (a, b), length in zip(zip(points[:-1], points[1:]), lengths):
        if left <= length and length > 0.0:
            f = left / length
            return a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])
        left -= length
    return points[-1]


def actuator_face(act: Actuator, position: float) -> str:
    """Return the face colour of an actuator at ``position``: a transfer unit's shows whether
    it is raised to its engage height (it carries the parts) or not."""
    if act.kind == 'transfer':
        return TRANSFER_UP if position >= act.engage_height else TRANSFER_DOWN
    return ACTUATOR_FACE


def _transfer_arrow(ax, act: Actuator, FancyArrow) -> None:
    """Draw the carrying direction of a transfer unit's rollers inside its footprint."""
    if act.surface_speed == 0.0:
        return
    sign = 1.0 if act.surface_speed > 0 else -1.0
    dx, dy = sign * act.axis[0], sign * act.axis[1]
    half = 0.3 * act.length
    ax.add_patch(FancyArrow(act.base[0] - half * dx, act.base[1] - half * dy, 2 * half * dx,
                            2 * half * dy, width=0.08 * act.width, head_width=0.3 * act.width,
                            head_length=min(0.2 * act.length, 0.3 * act.width),
                            length_includes_head=True, fc='#0b2f55', ec='none', alpha=0.7,
                            zorder=6))


def draw_actuators(ax, cell: Cell, positions: Sequence[float], *, stroke: bool = True,
                   labels: bool = True) -> list:
    """Draw every actuator at ``positions`` [m or rad]; with ``stroke`` its swept range dashed.

    :return: the actuator patches (in cell order), for animation.
    """
    from matplotlib.patches import FancyArrow, Polygon

    patches = []
    for act, position in zip(cell.actuators, positions):
        low, high = act.position_range
        if stroke:
            if act.kind == 'pusher':
                swept = _hull(actuator_outline(act, low) + actuator_outline(act, high))
                ax.add_patch(Polygon(swept, closed=True, fill=False, ec=ACTUATOR_FACE, lw=0.9,
                                     ls='--', zorder=3))
            elif act.kind == 'diverter':
                for end in (low, high):
                    ax.add_patch(Polygon(actuator_outline(act, end), closed=True, fill=False,
                                         ec=ACTUATOR_FACE, lw=0.9, ls='--', zorder=3))
        if act.kind == 'transfer':   # rollers across the carrying axis
            hatch = '||' if abs(act.axis[0]) >= abs(act.axis[1]) else '--'
            patch = Polygon(actuator_outline(act, position), closed=True,
                            fc=actuator_face(act, position), ec='#0b2f55', lw=0.6, zorder=5,
                            hatch=hatch)
        else:
            patch = Polygon(actuator_outline(act, position), closed=True, fc=ACTUATOR_FACE,
                            ec='#8a6a00', lw=0.6, zorder=5,
                            hatch='....' if act.kind == 'stopper' else None)
        ax.add_patch(patch)
        patches.append(patch)
        if act.kind == 'transfer':
            _transfer_arrow(ax, act, FancyArrow)
        if labels:
            unit = 'rad' if act.is_rotary else 'm'
            what = 'lift' if act.kind in ('stopper', 'transfer') else 'stroke'
            name = act.name if act.name == act.kind else f'{act.name} ({act.kind})'
            text = f'{name}: {what} {low:g}..{high:g} {unit}'
            if act.kind == 'transfer':
                text += f', rollers {act.surface_speed:g} m/s'
            _label(ax, act.base[0], act.base[1], text, '#8a6a00', dy=1.0)
    return patches


def _hull(points: Sequence[Tuple[float, float]]) -> List[Tuple[float, float]]:
    """Return the convex hull of ``points`` (monotone chain), counter-clockwise."""
    pts = sorted(set(points))
    if len(pts) <= 2:
        return list(pts)

    def cross(o, a, b) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: List[Tuple[float, float]] = []
    upper: List[Tuple[float, float]] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def draw_barriers(ax, cell: Cell, *, labels: bool = True) -> list:
    """Draw every light barrier as its beam (free colour); return the line artists."""
    lines = []
    for barrier in cell.light_barriers:
        (x0, y0), (x1, y1) = barrier.start, barrier.end
        line, = ax.plot([x0, x1], [y0, y1], '-', color=BEAM_FREE, lw=1.6, zorder=6)
        ax.plot([x0, x1], [y0, y1], 'o', color=BEAM_FREE, ms=2.5, zorder=6)
        lines.append(line)
        if labels:
            _label(ax, x0, y0, f'{barrier.name} (beam {barrier.height * 1e3:g} mm)', BEAM_FREE,
                   dy=-1.0)
    return lines


def view_limits(cell: Cell, margin: float = 0.08) -> Tuple[float, float, float, float]:
    """Return (x0, x1, y0, y1) [m] holding every element of the cell plus ``margin`` [m]."""
    xs: List[float] = []
    ys: List[float] = []
    for belt in cell.belts:
        if belt.curve is not None:
            x0, y0, x1, y1 = belt.bounding_box()
            xs += [x0, x1]
            ys += [y0, y1]
            continue
        for x, y in belt.corners():
            xs.append(x)
            ys.append(y)
    for region in ([s.region for s in cell.sources] + [s.region for s in cell.sinks]
                   + [z.region for z in cell.zones]):
        xs += [region[0], region[2]]
        ys += [region[1], region[3]]
    for obstacle in cell.obstacles:
        r = max(obstacle.radius, 0.5 * obstacle.thickness)
        for x, y in obstacle.points:
            xs += [x - r, x + r]
            ys += [y - r, y + r]
    for act in cell.actuators:
        for position in act.position_range:
            for x, y in actuator_outline(act, position):
                xs.append(x)
                ys.append(y)
    for barrier in cell.light_barriers:
        xs += [barrier.start[0], barrier.end[0]]
        ys += [barrier.start[1], barrier.end[1]]
    return min(xs) - margin, max(xs) + margin, min(ys) - margin, max(ys) + margin


def label_room(limits: Tuple[float, float, float, float],
               min_ratio: float = 0.22) -> Tuple[float, float, float, float]:
    """Return ``limits`` (x0, x1, y0, y1) [m] widened in y to at least ``min_ratio`` of x.

    A long thin cell gets room above and below for the names of its elements.
    """
    x0, x1, y0, y1 = limits
    extra = max(0.0, min_ratio * (x1 - x0) - (y1 - y0))
    return x0, x1, y0 - 0.5 * extra, y1 + 0.5 * extra


def figure_size(limits: Tuple[float, float, float, float], width: float = 14.0,
                min_height: float = 3.0) -> Tuple[float, float]:
    """Return a figure size [in] of ``width`` whose axes keep the cell's aspect ratio."""
    x0, x1, y0, y1 = limits
    height = width * (y1 - y0) / max(x1 - x0, 1e-9) + 1.6
    return width, max(min_height, min(height, 2.0 * width))


def cell_figure(cell: Cell, *, width: float = 14.0, dpi: float = 110):
    """Return (figure, axes) of the cell's layout to scale, every element named.

    The labels are placed (none overlaps another or the ticks) for this ``dpi``.
    :param width: figure width [in].
    """
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    limits = label_room(view_limits(cell))
    fig, ax = plt.subplots(figsize=figure_size(limits, width), dpi=dpi)
    draw_static(ax, cell)
    draw_actuators(ax, cell, [a.initial_position for a in cell.actuators])
    draw_barriers(ax, cell)
    ax.set_xlim(limits[0], limits[1])
    ax.set_ylim(limits[2], limits[3])
    ax.set_aspect('equal')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.grid(alpha=0.2, lw=0.5)
    ax.set_title(f"cell '{cell.settings.name}' (frame {cell.settings.frame_id}, to scale)",
                 fontsize=10)
    fig.tight_layout()
    place_labels(ax)
    return fig, ax


def plot_cell(cell: Cell, path: str, *, dpi: int = 110, width: float = 14.0) -> str:
    """Write a PNG of the cell's layout to scale, every element named; return ``path``.

    :param width: figure width [in].
    """
    from matplotlib import pyplot as plt

    fig, _ = cell_figure(cell, width=width, dpi=dpi)
    fig.savefig(path, dpi=dpi, bbox_inches='tight', pad_inches=0.1)
    plt.close(fig)
    return path
