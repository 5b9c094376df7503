"""Draw a whole plant to scale: every cell at its placement, every link as an arrow.

Each cell is drawn as :func:`~conveyor_twin.viz.cell_drawing.draw_static` draws it (belts,
walls, sources, sinks, zones, actuators, light barriers), moved and turned to its
``placement`` in the plant frame, inside a dashed outline with its name. A link is an arrow
from its exit (the sink's centre or the belt's end) to its entry (the belt's start or the
region's upstream edge), labelled with its name, delay and capacity. Units: m, plant frame.

``conveyor-twin plot PLANT.yaml -o plant.png`` calls :func:`plot_plant_main`.
"""

import argparse
import math
from pathlib import Path
import sys
from typing import List, Optional, Sequence, Tuple

from conveyor_twin.plant.model import EndFrame, Link, Placement, Plant, PlantCell

CELL_EDGE = '#2c3e50'
LINK_COLOURS = ('#c0392b', '#8e44ad', '#16a085', '#d35400', '#2980b9', '#7f8c8d')
NAME_SIZE = 10
LINK_SIZE = 8


def is_plant_file(path: str) -> bool:
    """Return True if ``path`` is a YAML file whose top level has a ``plant`` section."""
    import yaml
    if not path.lower().endswith(('.yaml', '.yml')):
        return False
    try:
        data = yaml.safe_load(Path(path).read_text('utf-8'))
    except (OSError, ValueError, yaml.YAMLError, RecursionError):
        return False
    return isinstance(data, dict) and 'plant' in data


def to_plant(p: Placement, x: float, y: float) -> Tuple[float, float]:
    """Return the plant-frame point [m] of the cell-frame point (x, y) [m]."""
    c, s = math.cos(p.yaw), math.sin(p.yaw)
    return p.x + c * x - s * y, p.y + s * x + c * y


def cell_outline(plant: Plant, cell: PlantCell) -> List[Tuple[float, float]]:
    """Return the plant-frame corners [m] of the cell's extent (its elements and its links'
    exits and entries, bounded in its own frame, turned to its placement)."""
    from conveyor_twin.plant.geometry import end_rect
    from conveyor_twin.viz.cell_drawing import view_limits
    margin = 0.03
    x0, x1, y0, y1 = view_limits(cell.cell, margin=margin)
    ends = [end_rect(k.exit) for k in plant.links_from(cell.name)]
    ends += [end_rect(k.entry) for k in plant.links_to(cell.name)]
    for a, b, c, d in ends:
        x0, y0 = min(x0, a - margin), min(y0, b - margin)
        x1, y1 = max(x1, c + margin), max(y1, d + margin)
    return [to_plant(cell.placement, x, y) for x, y in ((x0, y0), (x1, y0), (x1, y1),
                                                         (x0, y1))]


def link_points(plant: Plant, link: Link) -> Tuple[Tuple[float, float], Tuple[float, float]]:
    """Return the plant-frame points [m] of a link's exit and entry (the frames' origins)."""
    def origin(cell: str, f: EndFrame) -> Tuple[float, float]:
        return to_plant(plant.cell(cell).placement, f.x, f.y)
    return origin(link.source.cell, link.exit), origin(link.target.cell, link.entry)


def plant_limits(plant: Plant, margin: float = 0.15) -> Tuple[float, float, float, float]:
    """Return (x0, x1, y0, y1) [m] holding every cell of the plant plus ``margin`` [m]."""
    pts = [pt for c in plant.cells for pt in cell_outline(plant, c)]
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    return min(xs) - margin, max(xs) + margin, min(ys) - margin, max(ys) + margin


def _draw_cell(ax, plant: Plant, cell: PlantCell) -> None:
    """Draw one cell at its placement (no element names: the plant is the subject)."""
    from matplotlib.patches import Polygon
    from matplotlib.transforms import Affine2D

    from conveyor_twin.viz.cell_drawing import draw_actuators, draw_barriers, draw_static
    before = set(map(id, ax.get_children()))
    draw_static(ax, cell.cell, labels=False)
    draw_actuators(ax, cell.cell, [a.initial_position for a in cell.cell.actuators],
                   labels=False)
    draw_barriers(ax, cell.cell, labels=False)
    p = cell.placement
    move = Affine2D().rotate(p.yaw).translate(p.x, p.y) + ax.transData
    for artist in ax.get_children():
        if id(artist) not in before:
            artist.set_transform(move)
    ax.add_patch(Polygon(cell_outline(plant, cell), closed=True, fill=False, ec=CELL_EDGE, lw=0.9,
                         ls=(0, (4, 3)), zorder=7))


def _cell_name(ax, plant: Plant, cell: PlantCell, above: bool):
    pts = cell_outline(plant, cell)
    xs, ys = [q[0] for q in pts], [q[1] for q in pts]
    x = 0.5 * (min(xs) + max(xs))
    y, va = (max(ys), 'bottom') if above else (min(ys), 'top')
    name = cell.name if cell.file.endswith(f'{cell.name}.yaml') else (
        f'{cell.name} ({Path(cell.file).name})')
    return ax.annotate(name, (x, y), xytext=(0, 3 if above else -3),
                       textcoords='offset points', ha='center', va=va, fontsize=NAME_SIZE,
                       fontweight='bold', color=CELL_EDGE, zorder=9)


def end_outline(plant: Plant, cell: str, f: EndFrame) -> List[Tuple[float, float]]:
    """Return the plant-frame corners [m] of a link end's rectangle."""
    c, s = math.cos(f.yaw), math.sin(f.yaw)
    p = plant.cell(cell).placement
    return [to_plant(p, f.x + c * u - s * v, f.y + s * u + c * v)
            for u, v in ((f.x0, -f.half_width), (f.x1, -f.half_width),
                         (f.x1, f.half_width), (f.x0, f.half_width))]


def _draw_link(ax, plant: Plant, link: Link, colour: str, side: float):
    from matplotlib.patches import FancyArrowPatch, Polygon
    for cell, f in ((link.source.cell, link.exit), (link.target.cell, link.entry)):
        ax.add_patch(Polygon(end_outline(plant, cell, f), closed=True, fc=colour, ec=colour,
                             alpha=0.25, lw=1.0, zorder=7))
    (x0, y0), (x1, y1) = link_points(plant, link)
    ax.add_patch(FancyArrowPatch((x0, y0), (x1, y1), arrowstyle='-|>', mutation_scale=14,
                                 lw=1.8, color=colour, zorder=8, shrinkA=0, shrinkB=0,
                                 connectionstyle='arc3,rad=0.0'))
    ax.plot([x0], [y0], 'o', ms=4, color=colour, zorder=8)
    delay = link.delay_steps * plant.step
    cap = f', capacity {link.capacity}' if link.capacity else ''
    text = f'{link.name}\n{delay:g} s{cap}'
    mx, my = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
    return ax.annotate(text, (mx, my), xytext=(0, 30 * side), textcoords='offset points',
                       ha='center', va='bottom' if side > 0 else 'top', fontsize=LINK_SIZE,
                       color=colour, zorder=9,
                       arrowprops=dict(arrowstyle='-', color=colour, lw=0.6),
                       bbox=dict(boxstyle='round,pad=0.2', fc='white', ec=colour, lw=0.6,
                                 alpha=0.9))


#: Offsets tried for a link's label [points]: (x, y), y away from the plant's centre line.
LABEL_OFFSETS = ((0, 30), (-70, 30), (70, 30), (0, 58), (-70, 58), (70, 58), (-130, 30),
                 (130, 30), (0, 86), (-130, 58), (130, 58))


def _place(fig, ax, fixed: list, labels: list) -> None:
    """Move each link label to the first offset where it overlaps no other text (cell names
    and the labels placed before it) and stays inside the axes."""
    renderer = fig.canvas.get_renderer()
    taken = [text_box(t, renderer) for t in fixed]
    frame = ax.get_window_extent(renderer)
    for label, side in labels:
        for dx, dy in LABEL_OFFSETS:
            label.set_position((dx, dy * side))
            box = text_box(label, renderer)
            inside = (box.x0 >= frame.x0 and box.x1 <= frame.x1 and box.y0 >= frame.y0
                      and box.y1 <= frame.y1)
            if inside and not any(box.overlaps(t) for t in taken):
                break
        taken.append(text_box(label, renderer))


def text_box(text, renderer):
    """Return the display box of a text or an annotation's text (not its leader line), with
    room for its frame [pixels]."""
    from matplotlib.text import Text
    return Text.get_window_extent(text, renderer).padded(4)


def plant_figure(plant: Plant, *, width: float = 16.0, dpi: float = 110):
    """Return (figure, axes) of the whole plant to scale: cells at their placements, links
    as arrows, every cell and link named.

    :param width: figure width [in].
    """
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt

    x0, x1, y0, y1 = plant_limits(plant)
    # room above and below for the names
    extra = max(0.25 * (y1 - y0), 0.06 * (x1 - x0))
    y0, y1 = y0 - extra, y1 + extra
    height = width * (y1 - y0) / max(x1 - x0, 1e-9) + 1.2
    fig, ax = plt.subplots(figsize=(width, max(3.0, min(height, 1.5 * width))), dpi=dpi)
    centre_y = 0.5 * (y0 + y1)
    for cell in plant.cells:
        _draw_cell(ax, plant, cell)
    names = []
    for cell in plant.cells:
        ys = [q[1] for q in cell_outline(plant, cell)]
        names.append(_cell_name(ax, plant, cell, above=0.5 * (min(ys) + max(ys)) >= centre_y - 1e-9))
    labels = []
    for k, link in enumerate(plant.links):
        (_, ya), (_, yb) = link_points(plant, link)
        side = 1.0 if 0.5 * (ya + yb) >= centre_y - 1e-9 else -1.0
        if k % 2 and abs(ya - yb) < 1e-9:
            side = -side
        labels.append((_draw_link(ax, plant, link, LINK_COLOURS[k % len(LINK_COLOURS)],
                                  side), side))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect('equal')
    ax.set_xlabel('x [m] (plant frame)')
    ax.set_ylabel('y [m]')
    ax.grid(alpha=0.2, lw=0.5)
    ax.set_title(f"plant '{plant.name}': {len(plant.cells)} cells, {len(plant.links)} links "
                 '(to scale; arrows: exit to entry, with delay and capacity)', fontsize=11)
    fig.tight_layout()
    _place(fig, ax, names, labels)
    return fig, ax


def plot_plant(plant: Plant, path: str, *, width: float = 16.0, dpi: int = 110) -> str:
    """Write a PNG of the whole plant (:func:`plant_figure`); return ``path``."""
    from matplotlib import pyplot as plt
    fig, _ = plant_figure(plant, width=width, dpi=dpi)
    fig.savefig(path, dpi=dpi, bbox_inches='tight', pad_inches=0.1)
    plt.close(fig)
    return path


def plot_plant_main(argv: Sequence[str], out: Optional[object] = None) -> int:
    """``conveyor-twin plot PLANT.yaml -o plant.png``: return 0, or 1 if the plant (or a cell
    file it names) is invalid."""
    from conveyor_twin.cell.errors import CellError
    from conveyor_twin.plant.loader import load_plant
    p = argparse.ArgumentParser(prog='conveyor-twin plot',
                                description='Draw a plant of cells to scale with its links.')
    p.add_argument('plant', help='plant YAML file (docs/plant.md)')
    p.add_argument('-o', '--output', required=True, help='PNG file to write')
    p.add_argument('--width', type=float, default=16.0, help='figure width [in]')
    p.add_argument('--dpi', type=int, default=110, help='resolution [dots per inch]')
    args = p.parse_args(list(argv))
    try:
        plant = load_plant(args.plant)
    except CellError as exc:
        print(f'conveyor-twin plot: {exc}', file=sys.stderr)
        return 1
    path = plot_plant(plant, args.output, width=args.width, dpi=args.dpi)
    print(f'wrote {path}', file=out or sys.stdout)
    return 0
