"""``conveyor-twin plot``: a cell's layout, or PNG figures of a recording.

``conveyor-twin plot CELL.yaml -o cell.png`` (a ``.yaml``/``.yml`` file, or ``default`` for the
embedded cell) draws the cell to scale, every element named: belts with their direction,
obstacles, actuators with their stroke, light barriers, sources, sinks, zones with their policy.

``conveyor-twin plot RUN.mcap -o DIR`` writes the figures of a recording into DIR.

Figures (each only when the recording has the topic):

- ``trajectories_xy.png``: x-y paths of a selection of parts over every sampled position;
- ``trajectories_x.png``: x position against time of the same parts;
- ``density.png``: the macro density (``imshow`` of each zone's grid in the cell frame) at the
  times of ``--times``, one panel per time;
- ``light_barriers.png``: blocked (1) / free (0) against time per barrier, edges marked
  (▼ above: became blocked, ▲ below: became free, at their interpolated time);
- ``belt_speeds.png``: commanded (dashed) and actual speed against time per belt;
- ``actuators.png``: commanded and actual position against time per actuator.

A figure without data (a cell without actuators, a recording without density) is not written;
a line on stderr names it and says why. The trajectories are drawn over the recording's cell;
the density uses the colour map and scale of ``animate`` (0 to the cell's ρ_max).

Times are simulation time [s]. Exit codes: 0 figures written, 1 the cell or recording cannot be
read.
"""

import argparse
import os
import sys
from typing import List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record import series as series_mod
from conveyor_twin.wire.cdr import CdrError

DEFAULT_TIMES = (0.0, 0.5, 1.0, 2.0, 4.0, 6.0)
DEFAULT_PARTS = 8
#: Part-state messages kept by default (the stride is chosen to stay near this) [1].
PART_MESSAGES = 2000
#: Background dots drawn at most in the x-y figure [1].
MAX_DOTS = 200_000
DPI = 120


def _figure(*args, **kwargs):
    import matplotlib
    matplotlib.use('Agg')
    from matplotlib import pyplot as plt
    return plt.subplots(*args, **kwargs)


def _save(fig, path: str, *, crop: bool = False) -> str:
    from matplotlib import pyplot as plt
    fig.savefig(path, dpi=DPI, **(dict(bbox_inches='tight', pad_inches=0.1) if crop else {}))
    plt.close(fig)
    return path


def plot_trajectories(parts: series_mod.PartSamples, ids: Sequence[int], out_dir: str,
                      title: str, cell=None) -> List[str]:
    """Write the x-y and x-t trajectory figures; return their paths.

    :param cell: the recording's cell, drawn under the x-y paths (as ``plot CELL.yaml``
        draws it, without the names), or None.
    """
    from conveyor_twin.viz import cell_drawing
    written = []
    if cell is not None:
        limits = cell_drawing.view_limits(cell, margin=0.03)
        fig, ax = _figure(figsize=cell_drawing.figure_size(limits, 10.0, min_height=3.5))
        cell_drawing.draw_static(ax, cell, labels=False)
        cell_drawing.draw_actuators(ax, cell, [a.initial_position for a in cell.actuators],
                                    labels=False)
        cell_drawing.draw_barriers(ax, cell, labels=False)
    else:
        fig, ax = _figure(figsize=(10, 4))
    stride = max(1, len(parts.x) // MAX_DOTS)
    ax.plot(parts.x[::stride], parts.y[::stride], ',', color='0.45', label='all parts',
            zorder=7)
    for pid in ids:
        sel = parts.id == pid
        ax.plot(parts.x[sel], parts.y[sel], '-', lw=1.2, label=f'part {pid}', zorder=8)
        ax.plot(parts.x[sel][:1], parts.y[sel][:1], 'o', ms=3, color=ax.lines[-1].get_color(),
                zorder=8)
    if cell is not None:
        ax.set_xlim(limits[0], limits[1])
        ax.set_ylim(limits[2], limits[3])
        ax.set_aspect('equal')
    else:
        ax.set_aspect('equal', adjustable='datalim')
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_title(f'{title}: part trajectories (x-y)')
    ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    written.append(_save(fig, os.path.join(out_dir, 'trajectories_xy.png'), crop=True))

    fig, ax = _figure(figsize=(10, 4))
    for pid in ids:
        sel = parts.id == pid
        ax.plot(parts.t[sel], parts.x[sel], '-', lw=1.2, label=f'part {pid}')
    ax.set_xlabel('simulation time [s]')
    ax.set_ylabel('x [m]')
    ax.set_title(f'{title}: x position of {len(ids)} parts')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc='upper left', ncol=2)
    fig.tight_layout()
    written.append(_save(fig, os.path.join(out_dir, 'trajectories_x.png')))
    return written


def plot_density(density: dict, out_dir: str, title: str,
                 rho_max: Optional[float] = None) -> List[str]:
    """Write one figure with a panel per snapshot; return its path (or nothing).

    :param rho_max: the cell's density cap [parts/m²], the top of the colour scale (None:
        the largest density shown).
    """
    fig = density_figure(density, title, rho_max)
    return [] if fig is None else [_save(fig, os.path.join(out_dir, 'density.png'))]


def density_figure(density: dict, title: str, rho_max: Optional[float] = None):
    """Return the density figure (a panel per snapshot time), or None without snapshots.

    Snapshots of the same message (times past the end of the recording) are drawn once.
    :param density: {requested time [s]: [DensityGridData, ...]}.
    :param rho_max: the cell's density cap [parts/m²] (None: unknown).
    """
    from conveyor_twin.viz import style
    snapshots = {}
    for t in sorted(density):
        key = tuple(g.stamp_ns for g in density[t])
        snapshots.setdefault(key, density[t])
    panels = list(snapshots.values())
    if not panels:
        return None
    grids = [g for panel in panels for g in panel]
    vmax = style.density_vmax(grids, rho_max)
    x0 = min(g.origin_x for g in grids)
    y0 = min(g.origin_y for g in grids)
    x1 = max(g.origin_x + g.resolution * g.density.shape[1] for g in grids)
    y1 = max(g.origin_y + g.resolution * g.density.shape[0] for g in grids)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    fig, axes = _figure(len(panels), 1, squeeze=False, sharex=True, layout='constrained',
                        figsize=(10, 0.9 + len(panels) * (0.45 + max(1.0, 8.5 * aspect))))
    image = None
    for ax, panel in zip(axes[:, 0], panels):
        for g in panel:
            ny, nx = g.density.shape
            image = ax.imshow(g.density, origin='lower', cmap=style.DENSITY_CMAP, vmin=0.0,
                              vmax=vmax, interpolation='nearest',
                              extent=(g.origin_x, g.origin_x + nx * g.resolution, g.origin_y,
                                      g.origin_y + ny * g.resolution))
        stamp = panel[0].stamp_ns / 1e9
        total = sum(g.total_parts for g in panel)
        ax.set_title(f't = {stamp:.3f} s ({total:.1f} parts)', fontsize=9)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_ylabel('y [m]')
    axes[-1, 0].set_xlabel('x [m]')
    fig.suptitle(f'{title}: macro density ({style.density_scale_text(vmax, rho_max)})')
    if image is not None:
        fig.colorbar(image, ax=axes[:, 0].tolist(), label=style.DENSITY_LABEL, shrink=0.9)
    return fig


def plot_barriers(b: series_mod.BarrierSeries, out_dir: str, title: str) -> List[str]:
    """Write the light-barrier timeline figure; return its path."""
    names = list(b.names) or sorted({name for _, name, _ in b.edges})
    fig, ax = _figure(figsize=(10, 1.0 + 0.6 * max(len(names), 1)))
    for k, name in enumerate(names):
        base = 1.5 * k
        if len(b.t) and k < b.blocked.shape[1]:
            ax.step(b.t, base + b.blocked[:, k], where='post', lw=1.0)
        up = [t for t, n, blocked in b.edges if n == name and blocked]
        down = [t for t, n, blocked in b.edges if n == name and not blocked]
        ax.plot(up, np.full(len(up), base + 1.1), 'v', ms=4, color='tab:red',
                label='edge: blocked' if k == 0 else None)
        ax.plot(down, np.full(len(down), base - 0.1), '^', ms=4, color='tab:green',
                label='edge: freed' if k == 0 else None)
    ax.set_yticks([1.5 * k + 0.5 for k in range(len(names))])
    ax.set_yticklabels(names)
    ax.set_ylim(-0.4, 1.5 * max(len(names) - 1, 0) + 1.4)   # every name, blocked or not
    ax.set_xlabel('simulation time [s]')
    ax.set_title(f'{title}: light barriers (high = blocked)')
    ax.grid(axis='x', alpha=0.3)
    if b.edges:
        ax.legend(fontsize=7, loc='upper right')
    fig.tight_layout()
    return [_save(fig, os.path.join(out_dir, 'light_barriers.png'))]


def plot_named(s: series_mod.NamedSeries, out_dir: str, name: str, title: str,
               ylabel: str) -> List[str]:
    """Write a commanded (dashed) / actual (wide band) figure; return its path."""
    from conveyor_twin.viz import style
    fig, ax = _figure(figsize=(10, 4))
    style.commanded_and_actual(ax, s.t, s.actual, s.commanded, s.names)
    ax.set_xlabel('simulation time [s]')
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return [_save(fig, os.path.join(out_dir, name))]


def recording_figures(path: str, data: series_mod.Series, out_dir: str, title: str,
                      ids: Optional[Sequence[int]], count: int) -> Tuple[List[str], List[str]]:
    """Write every figure the recording has data for; return (paths written, skipped notes).

    :param ids: part ids to draw (None: the ``count`` longest-lived).
    """
    from conveyor_twin.viz.frames import recording_cell
    cell = recording_cell(path)
    written: List[str] = []
    skipped: List[str] = []
    if data.parts is not None and len(data.parts.id):
        if ids is None:
            ids = series_mod.pick_parts(data.parts, count).tolist()
        written += plot_trajectories(data.parts, ids, out_dir, title, cell)
    else:
        skipped.append('trajectories_xy.png, trajectories_x.png: no part states recorded')
    late = [t for t in sorted(data.density) if t > data.end_s + 1e-9]
    if late:
        skipped.append(f'density at t = {", ".join(f"{t:g}" for t in late)} s: after the end '
                       f'of the recording ({data.end_s:.3f} s), its last grid is shown once')
    if data.density:
        written += plot_density(data.density, out_dir, title,
                                cell.rho_max if cell is not None else None)
    else:
        skipped.append('density.png: no macro density recorded (no macro zone, or the topic '
                       'was not recorded)')
    if data.barriers is not None and (data.barriers.names or data.barriers.edges):
        written += plot_barriers(data.barriers, out_dir, title)
    else:
        skipped.append('light_barriers.png: no light barriers recorded')
    if data.belts is not None and data.belts.names:
        written += plot_named(data.belts, out_dir, 'belt_speeds.png',
                              f'{title}: belt speeds', 'speed [m/s]')
    else:
        skipped.append('belt_speeds.png: no belt states recorded')
    if data.actuators is not None and data.actuators.names:
        written += plot_named(data.actuators, out_dir, 'actuators.png',
                              f'{title}: actuator positions', 'position [m or rad]')
    elif data.actuators is not None:
        skipped.append('actuators.png: the cell has no actuators')
    else:
        skipped.append('actuators.png: no actuator states recorded')
    return written, skipped


def _floats(text: str) -> List[float]:
    return [float(v) for v in text.split(',') if v.strip()]


CELL_SUFFIXES = ('.yaml', '.yml')
#: Argument naming the embedded default cell.
DEFAULT_CELL = 'default'


def is_cell_argument(path: str) -> bool:
    """Return True if ``path`` names a cell (YAML file or ``default``), not a recording."""
    return path == DEFAULT_CELL or path.lower().endswith(CELL_SUFFIXES)


def plot_cell_main(argv: List[str]) -> int:
    """Draw a cell's layout into one PNG; return 0, or 1 if the cell is invalid."""
    from conveyor_twin.cell import CellError, load_cell
    from conveyor_twin.viz.cell_drawing import plot_cell
    p = argparse.ArgumentParser(prog='conveyor-twin plot', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('cell', help="cell YAML file ('default': the embedded default cell)")
    p.add_argument('-o', '--output', required=True, help='PNG file to write')
    p.add_argument('--width', type=float, default=14.0, help='figure width [in]')
    p.add_argument('--dpi', type=int, default=110, help='resolution [dots per inch]')
    args = p.parse_args(argv)
    try:
        cell = load_cell('' if args.cell == DEFAULT_CELL else args.cell)
    except CellError as err:
        print(f'conveyor-twin plot: invalid cell: {err}', file=sys.stderr)
        return 1
    if not args.output.lower().endswith('.png'):
        print(f'conveyor-twin plot: -o {args.output}: a cell is drawn as a .png file',
              file=sys.stderr)
        return 2
    parent = os.path.dirname(os.path.abspath(args.output))
    if not os.path.isdir(parent):
        print(f'conveyor-twin plot: -o {args.output}: directory {parent} does not exist',
              file=sys.stderr)
        return 2
    print(plot_cell(cell, args.output, dpi=args.dpi, width=args.width))
    return 0


def main(argv: List[str]) -> int:
    """Draw a cell (``.yaml``) or the figures of a recording; return 0, or 1 if unreadable."""
    words = [a for a in argv if not a.startswith('-')]
    from conveyor_twin.viz.plant_drawing import is_plant_file, plot_plant_main
    if any(is_plant_file(a) for a in words):   # a plant of cells: the whole plant
        return plot_plant_main(argv)
    if any(is_cell_argument(a) for a in words) and not any(
            a.lower().endswith('.mcap') for a in words):
        return plot_cell_main(argv)
    p = argparse.ArgumentParser(prog='conveyor-twin plot', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('file', help="MCAP recording (or a cell .yaml / 'default': its layout)")
    p.add_argument('-o', '--output', required=True, help='directory for the PNG files')
    p.add_argument('--times', type=_floats, default=list(DEFAULT_TIMES),
                   help='density snapshot times, comma separated [s] (default: 0,0.5,1,2,4,6)')
    p.add_argument('--parts', type=int, default=DEFAULT_PARTS,
                   help='number of parts to draw (the longest-lived)')
    p.add_argument('--part-ids', type=lambda s: [int(v) for v in s.split(',') if v.strip()],
                   default=None, help='ids of the parts to draw, comma separated')
    p.add_argument('--part-stride', type=int, default=0,
                   help=f'use every k-th parts message (0: about {PART_MESSAGES} messages)')
    args = p.parse_args(argv)
    import matplotlib
    matplotlib.use('Agg')
    from conveyor_twin.record import reader
    try:
        summary = reader.info(args.file)
        n_parts = sum(t['count'] for t in summary['topics'].values()
                      if t['type'] == series_mod.PARTS)
        stride = args.part_stride or max(1, -(-n_parts // PART_MESSAGES))
        data = series_mod.load(args.file, part_stride=stride, density_times=args.times)
    except (RecordingError, CdrError) as err:
        print(f'conveyor-twin plot: {err}', file=sys.stderr)
        return 1
    os.makedirs(args.output, exist_ok=True)
    title = summary['cell_name'] or os.path.basename(args.file)
    written, skipped = recording_figures(args.file, data, args.output, title, args.part_ids,
                                         args.parts)
    for note in skipped:
        print(f'conveyor-twin plot: skipped {note}', file=sys.stderr)
    for path in written:
        print(path)
    if not written:
        print(f'conveyor-twin plot: {args.file} has nothing to plot', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
