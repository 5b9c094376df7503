"""Render a recording's frames as a GIF (Pillow) or MP4 (ffmpeg) with matplotlib.

Top: the cell to scale (when the recording carries its cell) with the parts at their poses and
sizes, the macro density as a heat map, light barriers coloured by state and actuators at their
position (a transfer unit coloured up or down). Bottom: light-barrier states and belt speeds
against simulation time, with a cursor at the frame's time. The file is written to a temporary
name beside the output and moved into place when complete, so a failure leaves an existing
output untouched.
"""

import math
import os
import shutil
import sys
import tempfile
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.viz import cell_drawing, style
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


#: GIF frame delays are whole multiples of this [ms].
GIF_DELAY_UNIT_MS = 10
#: Highest frame rate of a GIF: viewers play shorter delays than 20 ms slower [1/s].
GIF_MAX_FPS = 50.0


def check_fps(suffix: str, fps: float) -> None:
    """:raises AnimationError: if a GIF cannot play at ``fps`` [1/s]."""
    if suffix == '.gif' and fps > GIF_MAX_FPS:
        raise AnimationError(f'--fps {fps:g}: a GIF plays at most {GIF_MAX_FPS:g} frames/s '
                             '(frame delays under 20 ms are slowed down by viewers); '
                             'lower --fps or write an .mp4')


def gif_delays(count: int, fps: float) -> List[int]:
    """Return ``count`` GIF frame delays [ms], multiples of 10 ms, that sum to ``count / fps``.

    Frame k starts at k / fps rounded to the 10 ms unit, so the delays alternate around
    1000 / fps (70, 60, 70 ms at 15 frames/s) and the total is exact to half a unit.
    """
    unit = GIF_DELAY_UNIT_MS
    starts = [int(round(k * 1000.0 / fps / unit)) * unit for k in range(count + 1)]
    return [max(unit, b - a) for a, b in zip(starts[:-1], starts[1:])]


def _writer(suffix: str, fps: float):
    from matplotlib import animation

    class ExactGifWriter(animation.PillowWriter):
        """Pillow's GIF writer with per-frame delays summing to the frame count / fps."""

        def finish(self) -> None:
            delays = gif_delays(len(self._frames), self.fps)
            self._frames[0].save(self.outfile, save_all=True, append_images=self._frames[1:],
                                 duration=delays, loop=0)

    if suffix == '.gif':
        return ExactGifWriter(fps=fps)
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


#: Height of the cell strip at least [in]; a longer cell widens the figure (up to
#: ``AUTO_WIDTH``), then the view gains room above and below.
MIN_SCENE_HEIGHT = 1.6
#: Range of the automatic figure width [in].
AUTO_WIDTH = (8.0, 13.0)
_LEFT, _RIGHT, _BAR = 0.7, 0.2, 1.0     # margins and colour bar room [in]
_TOP, _GAP, _LINES, _BOTTOM = 0.4, 0.75, 1.8, 0.5


def scene_layout(limits: Sequence[float], width: Optional[float],
                 density: bool) -> Tuple[float, float, Tuple[float, ...]]:
    """Return (figure width [in], strip height [in], view limits [m]) for a view to scale.

    The strip spans the figure's width; its height follows the view's aspect but is at least
    ``MIN_SCENE_HEIGHT`` (the automatic width grows first, then the view gains room in y) and
    at most the figure's width (the view gains room in x).
    :param width: figure width [in], or None to choose it.
    """
    x0, x1, y0, y1 = limits
    side = _LEFT + _RIGHT + (_BAR if density else 0.0)
    aspect = (y1 - y0) / max(x1 - x0, 1e-9)
    if width is None:
        width = min(max(MIN_SCENE_HEIGHT / max(aspect, 1e-9) + side, AUTO_WIDTH[0]),
                    AUTO_WIDTH[1])
    strip_w = max(width - side, 1.0)
    height = strip_w * aspect
    if height < MIN_SCENE_HEIGHT:
        extra = (MIN_SCENE_HEIGHT / strip_w * (x1 - x0) - (y1 - y0)) / 2.0
        y0, y1, height = y0 - extra, y1 + extra, MIN_SCENE_HEIGHT
    elif height > width:
        extra = ((y1 - y0) * strip_w / width - (x1 - x0)) / 2.0
        x0, x1, height = x0 - extra, x1 + extra, width
    return width, height, (x0, x1, y0, y1)


class _Scene:
    """The artists of one figure, updated frame by frame."""

    def __init__(self, data: RecordingFrames, *, view: Optional[Sequence[float]],
                 width: Optional[float]) -> None:
        import matplotlib
        matplotlib.use('Agg')
        from matplotlib import pyplot as plt
        from matplotlib.collections import EllipseCollection, PolyCollection

        self.data = data
        cell = data.cell
        grids = [g for f in data.frames for g in f.density.values()]
        width, scene_h, (x0, x1, y0, y1) = scene_layout(_limits(data, view), width,
                                                        bool(grids))
        fig_h = _TOP + scene_h + _GAP + _LINES + _BOTTOM
        self.fig = plt.figure(figsize=(width, fig_h))
        strip_w = width - _LEFT - _RIGHT - (_BAR if grids else 0.0)
        ax = self.ax = self.fig.add_axes((_LEFT / width, 1.0 - (_TOP + scene_h) / fig_h,
                                          strip_w / width, scene_h / fig_h))
        ax.set_xlim(x0, x1)
        ax.set_ylim(y0, y1)
        ax.set_aspect('equal', adjustable='datalim')
        ax.tick_params(labelsize=7)
        ax.set_xlabel('x [m]', fontsize=8, labelpad=1)
        ax.set_ylabel('y [m]', fontsize=8, labelpad=1)
        self.barrier_lines: List = []
        self.actuator_patches: List = []
        if cell is not None:
            cell_drawing.draw_static(ax, cell, labels=False)
            self.actuator_patches = cell_drawing.draw_actuators(
                ax, cell, [a.initial_position for a in cell.actuators], stroke=False,
                labels=False)
            self.barrier_lines = cell_drawing.draw_barriers(ax, cell, labels=False)
        rho_max = cell.rho_max if cell is not None and grids else None
        vmax = style.density_vmax(grids, rho_max)
        self.density_images = {}
        cmap = matplotlib.colormaps[style.DENSITY_CMAP].with_extremes(bad=(0.0, 0.0, 0.0, 0.0))
        for grid_ in grids:
            if grid_.zone in self.density_images:
                continue
            ny, nx = grid_.density.shape
            extent = (grid_.origin_x, grid_.origin_x + nx * grid_.resolution, grid_.origin_y,
                      grid_.origin_y + ny * grid_.resolution)
            self.density_images[grid_.zone] = ax.imshow(
                np.ma.masked_all((ny, nx)), origin='lower', extent=extent, cmap=cmap, vmin=0.0,
                vmax=vmax, interpolation='nearest', alpha=0.9, zorder=3)
        if self.density_images:
            cax = self.fig.add_axes(((_LEFT + strip_w + 0.12) / width,
                                     1.0 - (_TOP + scene_h) / fig_h, 0.12 / width,
                                     scene_h / fig_h))
            bar = self.fig.colorbar(next(iter(self.density_images.values())), cax=cax)
            bar.set_label(style.DENSITY_LABEL, fontsize=7, labelpad=2)
            bar.ax.tick_params(labelsize=6)
            self.density_scale = style.density_scale_text(vmax, rho_max)
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
        self._timelines(width, fig_h)

    def _timelines(self, width: float, fig_h: float) -> None:
        data = self.data
        names = data.barriers.names
        left_b = 0.25 + 0.06 * max([len(n) for n in names] + [4])  # barrier names [in]
        half = 0.5 * width
        bottom, height = _BOTTOM / fig_h, _LINES / fig_h
        ax_b = self.fig.add_axes((left_b / width, bottom, (half - 0.2 - left_b) / width,
                                  height))
        t, blocked, _ = data.barriers.arrays()
        for k, name in enumerate(names):
            ax_b.step(t, 1.5 * k + blocked[:, k], where='post', lw=0.9)
        ax_b.set_yticks([1.5 * k + 0.5 for k in range(len(names))])
        ax_b.set_yticklabels(names, fontsize=7)
        ax_b.set_ylim(-0.3, 1.5 * max(len(names) - 1, 0) + 1.3)   # every name, blocked or not
        ax_b.set_title('light barriers (high = blocked)', fontsize=8)
        ax_v = self.fig.add_axes(((half + 0.45) / width, bottom,
                                  (half - 0.45 - _RIGHT) / width, height))
        t_v, actual, commanded = data.belts.arrays()
        style.commanded_and_actual(ax_v, t_v, actual, commanded, data.belts.names,
                                   fontsize=6)
        ax_v.set_title('belt speeds [m/s]', fontsize=8)
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
                if act.kind == 'transfer':   # up (carrying) or down, per frame
                    patch.set_facecolor(cell_drawing.actuator_face(act, float(position)))
        for cursor in self.cursors:
            cursor.set_xdata([frame.t, frame.t])
        text = f'{self.name}: t = {frame.t:6.2f} s, {shown} parts (micro)'
        if self.density_images:
            text += f', {macro:.1f} parts (macro; {self.density_scale})'
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


def render(data: RecordingFrames, path: str, *, fps: float, dpi: int = 90,
           width: Optional[float] = None, view: Optional[Sequence[float]] = None,
           progress: Optional[Callable[[int, int], None]] = None) -> int:
    """Write the animation of ``data`` to ``path`` (.gif or .mp4); return the frame count.

    :param fps: frames per second of the file [1/s].
    :param dpi: resolution [dots per inch]; ``width`` [in] (None: from the view's aspect).
    :param view: (x0, x1) or (x0, x1, y0, y1) to show [m] (default: the whole cell).
    :param progress: called with (frames written, total) after every frame.
    :raises AnimationError: if the output cannot be written (the output is left untouched).
    """
    from matplotlib import pyplot as plt

    suffix = check_output(path)
    check_fps(suffix, fps)
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
