"""Render a recording's frames as a GIF (Pillow) or MP4 (ffmpeg) with matplotlib.

Top: the cell to scale (when the recording carries its cell) with the parts at their poses and
sizes, the macro density as a heat map, light barriers coloured by state and actuators at their
position. Bottom: light-barrier states and belt speeds against simulation time, with a cursor
at the frame's time. The file is written to a temporary name beside the output and moved into
place when complete, so a failure leaves an existing output untouched.
"""

import math
import os
import shutil
import sys
import tempfile
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.viz import cell_drawing
from conveyor_twin.viz.frames import Frame, RecordingFrames

FORMATS = ('.gif', '.mp4')
PART_COLOURS = ('#3b6fb6', '#e07b00', '#2e9e44', '#a23bb6')
DEFAULT_DISC_RADIUS = 0.005  # m, parts of a recording without its cell


class AnimationError(RuntimeError):
    """The animation cannot be written (format, missing encoder, output path)."""


def check_output(path: str) -> str:
    """Return the format (``.gif``/``.mp4``) of ``path``.

    :raises AnimationError: for another suffix, a missing directory, or ``.mp4`` without ffmpeg.
    """
    suffix = os.path.splitext(path)[1].lower()
    if suffix not in FORMATS:
        raise AnimationError(f'-o {path}: the output must end in .gif or .mp4')
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(parent):
        raise AnimationError(f'-o {path}: directory {parent} does not exist')
    if suffix == '.mp4' and shutil.which('ffmpeg') is None:
        raise AnimationError(f'-o {path}: writing MP4 needs ffmpeg, which is not installed '
                             '(apt-get install ffmpeg), or write a .gif')
    return suffix


def _writer(suffix: str, fps: float):
    from matplotlib import animation
    if suffix == '.gif':
        return animation.PillowWriter(fps=fps)
    return animation.FFMpegWriter(fps=fps, codec='h264', extra_args=['-pix_fmt', 'yuv420p'])


def _limits(data: RecordingFrames, view: Optional[Sequence[float]]) -> Tuple[float, ...]:
    if data.cell is not None:
        x0, x1, y0, y1 = cell_drawing.view_limits(data.cell, margin=0.03)
    else:
        xs = [f.parts.x for f in data.frames if f.parts is not None and len(f.parts.x)]
        ys = [f.parts.y for f in data.frames if f.parts is not None and len(f.parts.y)]
        grids = [g for f in data.frames for g in f.density.values()]
        lo_x = [float(np.min(v)) for v in xs] + [g.origin_x for g in grids]
        hi_x = [float(np.max(v)) for v in xs] + [
            g.origin_x + g.resolution * g.density.shape[1] for g in grids]
        lo_y = [float(np.min(v)) for v in ys] + [g.origin_y for g in grids]
        hi_y = [float(np.max(v)) for v in ys] + [
            g.origin_y + g.resolution * g.density.shape[0] for g in grids]
        x0, x1 = (min(lo_x), max(hi_x)) if lo_x else (0.0, 1.0)
        y0, y1 = (min(lo_y), max(hi_y)) if lo_y else (-0.5, 0.5)
        pad = 0.05 * max(x1 - x0, y1 - y0, 0.1)
        x0, x1, y0, y1 = x0 - pad, x1 + pad, y0 - pad, y1 + pad
    if view:
        x0, x1 = view[0], view[1]
        if len(view) == 4:
            y0, y1 = view[2], view[3]
    return x0, x1, y0, y1


class _Scene:
    """The artists of one figure, updated frame by frame."""

    def __init__(self, data: RecordingFrames, *, view: Optional[Sequence[float]],
                 width: float) -> None:
        import matplotlib
        matplotlib.use('Agg')
        from matplotlib import pyplot as plt
        from matplotlib.collections import EllipseCollection, PolyCollection

        self.data = data
        cell = data.cell
        x0, x1, y0, y1 = _limits(data, view)
        scene_h = width * (y1 - y0) / max(x1 - x0, 1e-9)
        scene_h = min(max(scene_h, 1.2), 1.2 * width)
        self.fig = plt.figure(figsize=(width, scene_h + 2.6))
        grid = self.fig.add_gridspec(2, 2, height_ratios=(scene_h, 2.0), hspace=0.35,
                                     wspace=0.25, left=0.07, right=0.98, top=0.93, bottom=0.12)
        ax = self.ax = self.fig.add_subplot(grid[0, :])
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect('equal')
        ax.tick_params(labelsize=7)
        ax.set_xlabel('x [m]', fontsize=8, labelpad=1)
        self.barrier_lines: List = []
        self.actuator_patches: List = []
        if cell is not None:
            cell_drawing.draw_static(ax, cell, labels=False)
            self.actuator_patches = cell_drawing.draw_actuators(
                ax, cell, [a.initial_position for a in cell.actuators], stroke=False,
                labels=False)
            self.barrier_lines = cell_drawing.draw_barriers(ax, cell, labels=False)
        grids = [g for f in data.frames for g in f.density.values()]
        vmax = cell.rho_max if cell is not None else max(
            [float(np.max(g.density)) for g in grids] + [1.0])
        self.density_images = {}
        cmap = matplotlib.colormaps['inferno_r'].with_extremes(bad=(0.0, 0.0, 0.0, 0.0))
        for grid_ in grids:
            if grid_.zone in self.density_images:
                continue
            ny, nx = grid_.density.shape
            extent = (grid_.origin_x, grid_.origin_x + nx * grid_.resolution, grid_.origin_y,
                      grid_.origin_y + ny * grid_.resolution)
            self.density_images[grid_.zone] = ax.imshow(
                np.ma.masked_all((ny, nx)), origin='lower', extent=extent, cmap=cmap, vmin=0.0,
                vmax=vmax, interpolation='nearest', alpha=0.85, zorder=3)
        if self.density_images:
            bar = self.fig.colorbar(next(iter(self.density_images.values())), ax=ax,
                                    fraction=0.025, pad=0.01)
            bar.set_label('density [parts/m²]', fontsize=7)
            bar.ax.tick_params(labelsize=6)
        self.discs = []
        self.boxes = []
        types = cell.part_types if cell is not None else ()
        count = max(len(types), 1)
        for index in range(count):
            colour = PART_COLOURS[index % len(PART_COLOURS)]
            pt = types[index] if types else None
            if pt is None or pt.shape == 'disc':
                coll = EllipseCollection([], [], [], units='xy', offsets=np.zeros((0, 2)),
                                         offset_transform=ax.transData, facecolors=colour,
                                         edgecolors='#1d1d1d', linewidths=0.2, zorder=7)
                ax.add_collection(coll)
                radius = pt.radius if pt is not None else DEFAULT_DISC_RADIUS
                self.discs.append((index, coll, radius))
            else:
                coll = PolyCollection([], facecolors=colour, edgecolors='#1d1d1d',
                                      linewidths=0.2, zorder=7)
                ax.add_collection(coll)
                self.boxes.append((index, coll, pt.length, pt.width))
        self.title = ax.set_title('', fontsize=9)
        self.name = cell.settings.name if cell is not None else os.path.basename(data.path)
        self.cursors = []
        self._timelines(grid)

    def _timelines(self, grid) -> None:
        data = self.data
        ax_b = self.fig.add_subplot(grid[1, 0])
        t, blocked, _ = data.barriers.arrays()
        for k, name in enumerate(data.barriers.names):
            ax_b.step(t, 1.5 * k + blocked[:, k], where='post', lw=0.9)
        ax_b.set_yticks([1.5 * k + 0.5 for k in range(len(data.barriers.names))])
        ax_b.set_yticklabels(data.barriers.names, fontsize=7)
        ax_b.set_title('light barriers (high = blocked)', fontsize=8)
        ax_v = self.fig.add_subplot(grid[1, 1])
        t_v, actual, commanded = data.belts.arrays()
        for k, name in enumerate(data.belts.names):
            line, = ax_v.plot(t_v, actual[:, k], '-', lw=1.1, label=name)
            if commanded.shape[1] > k:
                ax_v.plot(t_v, commanded[:, k], '--', lw=0.8, color=line.get_color())
        if data.belts.names:
            ax_v.legend(fontsize=6, loc='lower right')
        ax_v.set_title('belt speeds [m/s] (dashed: commanded)', fontsize=8)
        for ax in (ax_b, ax_v):
            ax.set_xlim(data.start_s, max(data.end_s, data.start_s + 1e-3))
            ax.set_xlabel('simulation time [s]', fontsize=7, labelpad=1)
            ax.tick_params(labelsize=6)
            ax.grid(alpha=0.3, lw=0.5)
            self.cursors.append(ax.axvline(data.start_s, color='k', lw=0.8))

    def update(self, frame: Frame) -> None:
        """Show ``frame``: parts, density, barrier colours, actuator poses, cursors, title."""
        parts = frame.parts
        shown = 0
        for index, coll, radius in self.discs:
            if parts is None:
                offsets = np.zeros((0, 2))
            else:
                sel = parts.part_type == index if self.data.cell is not None else slice(None)
                offsets = np.column_stack((parts.x[sel], parts.y[sel]))
            n = len(offsets)
            shown += n
            coll.set_offsets(offsets)
            coll.set_widths(np.full(n, 2.0 * radius))   # full axes [m]
            coll.set_heights(np.full(n, 2.0 * radius))
            coll.set_angles(np.zeros(n))
        for index, coll, length, width in self.boxes:
            verts = []
            if parts is not None:
                sel = parts.part_type == index
                verts = _box_vertices(parts.x[sel], parts.y[sel], parts.yaw[sel], length, width)
                shown += len(verts)
            coll.set_verts(verts)
        macro = 0.0
        for zone, image in self.density_images.items():
            grid = frame.density.get(zone)
            if grid is None:
                continue
            image.set_data(np.ma.masked_less_equal(grid.density, 1e-6))
            macro += grid.total_parts
        if frame.blocked is not None:
            for line, blocked in zip(self.barrier_lines, frame.blocked):
                line.set_color(cell_drawing.BEAM_BLOCKED if blocked else cell_drawing.BEAM_FREE)
                line.set_linewidth(2.4 if blocked else 1.6)
        if frame.actuator_position is not None and self.data.cell is not None:
            for patch, act, position in zip(self.actuator_patches, self.data.cell.actuators,
                                            frame.actuator_position):
                patch.set_xy(cell_drawing.actuator_outline(act, float(position)))
        for cursor in self.cursors:
            cursor.set_xdata([frame.t, frame.t])
        text = f'{self.name}: t = {frame.t:6.2f} s, {shown} parts (micro)'
        if self.density_images:
            text += f', {macro:.1f} parts (macro)'
        self.title.set_text(text)


def _box_vertices(x: np.ndarray, y: np.ndarray, yaw: np.ndarray, length: float,
                  width: float) -> np.ndarray:
    """Return (n, 4, 2) corners of boxes at poses ([m], [rad])."""
    corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * (0.5 * length,
                                                                       0.5 * width)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    vx = x[:, None] + c * corners[None, :, 0] - s * corners[None, :, 1]
    vy = y[:, None] + s * corners[None, :, 0] + c * corners[None, :, 1]
    return np.stack((vx, vy), axis=-1)


def progress_bar(done: int, total: int, width: int = 30) -> str:
    """Return a text progress bar, e.g. ``[#####.....]  12/40 frames``."""
    filled = int(math.floor(width * done / max(total, 1)))
    return f'[{"#" * filled}{"." * (width - filled)}] {done:>4}/{total} frames'


def render(data: RecordingFrames, path: str, *, fps: float, dpi: int = 80,
           width: float = 10.0, view: Optional[Sequence[float]] = None,
           progress: Optional[Callable[[int, int], None]] = None) -> int:
    """Write the animation of ``data`` to ``path`` (.gif or .mp4); return the frame count.

    :param fps: frames per second of the file [1/s].
    :param dpi: resolution [dots per inch]; ``width`` [in].
    :param view: (x0, x1) or (x0, x1, y0, y1) to show [m] (default: the whole cell).
    :param progress: called with (frames written, total) after every frame.
    :raises AnimationError: if the output cannot be written (the output is left untouched).
    """
    from matplotlib import pyplot as plt

    suffix = check_output(path)
    scene = _Scene(data, view=view, width=width)
    handle, tmp = tempfile.mkstemp(suffix=suffix, prefix='.animate-',
                                   dir=os.path.dirname(os.path.abspath(path)))
    os.close(handle)
    total = len(data.frames)
    try:
        writer = _writer(suffix, fps)
        with writer.saving(scene.fig, tmp, dpi):
            for k, frame in enumerate(data.frames):
                scene.update(frame)
                writer.grab_frame()
                if progress is not None:
                    progress(k + 1, total)
        os.chmod(tmp, 0o644)  # mkstemp made it private; the output is an ordinary file
        os.replace(tmp, path)
    except (OSError, RuntimeError, ValueError) as exc:
        raise AnimationError(f'cannot write {path}: {exc}') from None
    finally:
        plt.close(scene.fig)
        if os.path.exists(tmp):
            os.unlink(tmp)
    return total


def stderr_progress(done: int, total: int) -> None:
    """Print a progress bar on stderr (one updating line on a terminal)."""
    tty = sys.stderr.isatty()
    end = '' if tty and done < total else '\n'
    if tty or done == total or done % max(1, total // 10) == 0:
        print(('\r' if tty else '') + progress_bar(done, total), end=end, file=sys.stderr,
              flush=True)
