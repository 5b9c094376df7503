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

Times are simulation time [s]. Exit codes: 0 figures written, 1 the cell or recording cannot be
read.
"""

import argparse
import os
import sys
from typing import List, Optional, Sequence

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


def _save(fig, path: str) -> str:
    from matplotlib import pyplot as plt
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def plot_trajectories(parts: series_mod.PartSamples, ids: Sequence[int], out_dir: str,
                      title: str) -> List[str]:
    """Write the x-y and x-t trajectory figures; return their paths."""
    written = []
    fig, ax = _figure(figsize=(10, 4))
    stride = max(1, len(parts.x) // MAX_DOTS)
    ax.plot(parts.x[::stride], parts.y[::stride], ',', color='0.75', label='all parts')
    for pid in ids:
        sel = parts.id == pid
        ax.plot(parts.x[sel], parts.y[sel], '-', lw=1.2, label=f'part {pid}')
        ax.plot(parts.x[sel][:1], parts.y[sel][:1], 'o', ms=3, color=ax.lines[-1].get_color())
    ax.set_xlabel('x [m]')
    ax.set_ylabel('y [m]')
    ax.set_aspect('equal', adjustable='datalim')
    ax.set_title(f'{title}: part trajectories (x-y)')
    ax.legend(fontsize=7, loc='upper right', ncol=2)
    fig.tight_layout()
    written.append(_save(fig, os.path.join(out_dir, 'trajectories_xy.png')))

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


def plot_density(density: dict, out_dir: str, title: str) -> List[str]:
    """Write one figure with a panel per snapshot time; return its path (or nothing)."""
    times = sorted(density)
    if not times:
        return []
    grids = [g for t in times for g in density[t]]
    vmax = max(float(np.max(g.density)) for g in grids) or 1.0
    x0 = min(g.origin_x for g in grids)
    y0 = min(g.origin_y for g in grids)
    x1 = max(g.origin_x + g.resolution * g.density.shape[1] for g in grids)
    y1 = max(g.origin_y + g.resolution * g.density.shape[0] for g in grids)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    fig, axes = _figure(len(times), 1, figsize=(10, 0.6 + len(times) * max(1.0, 10 * aspect)),
                        squeeze=False, sharex=True)
    image = None
    for ax, t in zip(axes[:, 0], times):
        for g in density[t]:
            ny, nx = g.density.shape
            image = ax.imshow(g.density, origin='lower', cmap='viridis', vmin=0.0, vmax=vmax,
                              extent=(g.origin_x, g.origin_x + nx * g.resolution, g.origin_y,
                                      g.origin_y + ny * g.resolution), interpolation='nearest')
        stamp = density[t][0].stamp_ns / 1e9
        total = sum(g.total_parts for g in density[t])
        ax.set_title(f't = {stamp:.3f} s ({total:.1f} parts)', fontsize=9)
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_ylabel('y [m]')
    axes[-1, 0].set_xlabel('x [m]')
    fig.suptitle(f'{title}: macro density')
    fig.tight_layout()
    if image is not None:
        fig.colorbar(image, ax=axes[:, 0].tolist(), label='density [parts/m²]', shrink=0.9)
    return [_save(fig, os.path.join(out_dir, 'density.png'))]


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
    ax.set_xlabel('simulation time [s]')
    ax.set_title(f'{title}: light barriers (high = blocked)')
    ax.grid(axis='x', alpha=0.3)
    if b.edges:
        ax.legend(fontsize=7, loc='upper right')
    fig.tight_layout()
    return [_save(fig, os.path.join(out_dir, 'light_barriers.png'))]


def plot_named(s: series_mod.NamedSeries, out_dir: str, name: str, title: str,
               ylabel: str) -> List[str]:
    """Write a commanded (dashed) / actual (solid) figure; return its path."""
    fig, ax = _figure(figsize=(10, 4))
    for k, label in enumerate(s.names):
        line, = ax.plot(s.t, s.actual[:, k], '-', lw=1.4, label=f'{label} actual')
        ax.plot(s.t, s.commanded[:, k], '--', lw=1.0, color=line.get_color(),
                label=f'{label} commanded')
    ax.set_xlabel('simulation time [s]')
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return [_save(fig, os.path.join(out_dir, name))]


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
    written: List[str] = []
    if data.parts is not None and len(data.parts.id):
        ids: Optional[Sequence[int]] = args.part_ids
        if ids is None:
            ids = series_mod.pick_parts(data.parts, args.parts).tolist()
        written += plot_trajectories(data.parts, ids, args.output, title)
    written += plot_density(data.density, args.output, title)
    if data.barriers is not None:
        written += plot_barriers(data.barriers, args.output, title)
    if data.belts is not None:
        written += plot_named(data.belts, args.output, 'belt_speeds.png',
                              f'{title}: belt speeds', 'speed [m/s]')
    if data.actuators is not None:
        written += plot_named(data.actuators, args.output, 'actuators.png',
                              f'{title}: actuator positions', 'position [m or rad]')
    for path in written:
        print(path)
    if not written:
        print(f'conveyor-twin plot: {args.file} has nothing to plot', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
