"""Pictures are readable: labels apart, nothing clipped, one density style, exact GIF timing."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from conveyor_twin.cell import default_cell_text, load_cell
from conveyor_twin.cli import main as cli_main
from conveyor_twin.cli import plot as plot_verb
from conveyor_twin.record import series as series_mod
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.viz import animation, cell_drawing, label_placement, style
from conveyor_twin.viz.frames import load_frames
from conveyor_twin.wire import cdr

from ..record.synthetic import conveyor_run

Image = pytest.importorskip('PIL.Image')

EXAMPLES = Path(cell_drawing.__file__).resolve().parents[1] / 'cell' / 'examples'
SHIPPED = ['default'] + sorted(p.name for p in EXAMPLES.glob('*.yaml'))


def _cell(name: str):
    return load_cell() if name == 'default' else load_cell(EXAMPLES / name)


def _area(a, b) -> float:
    w = min(a.x1, b.x1) - max(a.x0, b.x0)
    h = min(a.y1, b.y1) - max(a.y0, b.y0)
    return w * h if w > 0 and h > 0 else 0.0


def _shown_ticks(ax) -> list:
    """The tick labels drawn: their tick lies within the view."""
    shown = []
    for axis in (ax.xaxis, ax.yaxis):
        low, high = sorted(axis.get_view_interval())
        for tick in axis.get_major_ticks():
            if low - 1e-9 <= tick.get_loc() <= high + 1e-9 and tick.label1.get_text():
                shown.append(tick.label1)
    return shown


def _texts_inside_figure(fig) -> None:
    """Every text drawn in ``fig`` lies within the figure (nothing clipped at its edge)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    frame = fig.bbox
    texts = list(fig.texts)
    for ax in fig.axes:
        texts += _shown_ticks(ax) + [ax.title, ax.xaxis.label, ax.yaxis.label] + ax.texts
        if ax.get_legend() is not None:
            texts += ax.get_legend().get_texts()
    for text in texts:
        if not text.get_visible() or not text.get_text().strip():
            continue
        box = text.get_window_extent(renderer)
        assert frame.x0 - 0.5 <= box.x0 and box.x1 <= frame.x1 + 0.5, text.get_text()
        assert frame.y0 - 0.5 <= box.y0 and box.y1 <= frame.y1 + 0.5, text.get_text()


@pytest.fixture(scope='module')
def run_file(tmp_path_factory) -> str:
    path = str(tmp_path_factory.mktemp('layout') / 'run.mcap')
    conveyor_run(path, seconds=2.0, parts=6)
    return path


@pytest.fixture(scope='module')
def cell_run(tmp_path_factory) -> str:
    """A recording carrying the default cell: parts, belts, and actuator states of none."""
    path = str(tmp_path_factory.mktemp('cellrun') / 'cell.mcap')
    with McapRecorder(path, cell_yaml=default_cell_text(), seed=1, step_ns=1_000_000) as rec:
        rec.add_topic('/parts', series_mod.PARTS)
        rec.add_topic('/belt_states', series_mod.BELTS)
        rec.add_topic('/actuator_states', series_mod.ACTUATORS)
        for step in range(0, 1000, 10):
            t = step * 1_000_000
            ids = np.arange(1, 4, dtype=np.uint32)
            x = 0.1 + 0.5 * step * 1e-3 + 0.2 * np.arange(3)
            y = np.array([-0.1, 0.0, 0.1])
            rec.record('/parts', t, cdr.encode_part_states(
                t, 'cell', step, ids, np.zeros(3, np.uint16), x, y, np.zeros(3),
                np.full(3, 0.5), np.zeros(3), np.zeros(3)))
            rec.record('/belt_states', t, cdr.encode_belt_states(
                t, 'cell', ('main',), np.array([0.5]), np.array([0.5])))
            rec.record('/actuator_states', t, cdr.encode_actuator_states(
                t, 'cell', (), np.zeros(0), np.zeros(0)))
    return path


# --- cell plots -------------------------------------------------------------------------

@pytest.mark.parametrize('name', SHIPPED)
def test_cell_labels_overlap_neither_each_other_nor_the_ticks(name):
    from matplotlib import pyplot as plt
    cell = _cell(name)
    fig, ax = cell_drawing.cell_figure(cell)   # the size and resolution of `plot CELL.yaml`
    try:
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        labels = label_placement.labels_of(ax)
        expected = (len(cell.belts) + len(cell.zones) + len(cell.sources) + len(cell.sinks)
                    + len(cell.obstacles) + len(cell.actuators) + len(cell.light_barriers))
        assert len(labels) == expected  # every element named
        # the label's white box (an annotation's own extent includes its leader line)
        boxes = [(label.get_text(), label.get_bbox_patch().get_window_extent(renderer))
                 for label in labels]
        for i, (text_a, a) in enumerate(boxes):
            for text_b, b in boxes[i + 1:]:
                assert _area(a, b) == 0.0, f'{name}: {text_a!r} overlaps {text_b!r}'
        ticks = _shown_ticks(ax)
        assert len(ticks) >= 4
        axes_box = ax.get_window_extent(renderer)
        for text, box in boxes:
            for tick in ticks:
                assert _area(box, tick.get_window_extent(renderer)) == 0.0, \
                    f'{name}: {text!r} overlaps tick {tick.get_text()!r}'
            assert axes_box.x0 <= box.x0 and box.x1 <= axes_box.x1, f'{name}: {text!r}'
            assert axes_box.y0 <= box.y0 and box.y1 <= axes_box.y1, f'{name}: {text!r}'
        _texts_inside_figure(fig)
    finally:
        plt.close(fig)


def test_a_label_away_from_its_anchor_has_a_leader_line():
    from matplotlib import pyplot as plt
    fig, ax = cell_drawing.cell_figure(_cell('sorting.yaml'))
    try:
        far = [label for label in label_placement.labels_of(ax)
               if np.hypot(*label.xyann) > 20.0]   # [points]
        assert far
        assert all(label.arrow_patch is not None and label.arrow_patch.get_visible()
                   for label in far)
    finally:
        plt.close(fig)


# --- animation --------------------------------------------------------------------------

def test_gif_delays_add_up_to_the_frame_count_over_the_rate():
    delays = animation.gif_delays(15, 15.0)
    assert delays[:3] == [70, 60, 70] and sum(delays) == 1000
    for fps in (7.0, 12.0, 15.0, 24.0, 30.0, 50.0):
        for count in (1, 2, 37, 100):
            delays = animation.gif_delays(count, fps)
            assert all(d % 10 == 0 and d >= 20 for d in delays)
            assert abs(sum(delays) - 1000.0 * count / fps) <= 5.0


@pytest.mark.parametrize('fps,speed', [(15.0, 1.0), (12.0, 0.5)])
def test_the_gif_plays_at_the_stated_speed(run_file, tmp_path, capsys, fps, speed):
    out = tmp_path / 'run.gif'
    assert cli_main(['animate', run_file, '-o', str(out), '--fps', f'{fps:g}', '--speed',
                     f'{speed:g}', '--dpi', '20', '--width', '5', '--quiet']) == 0
    data = load_frames(run_file, fps=fps, speed=speed)
    simulated = len(data.frames) * speed / fps   # each frame shows speed / fps of simulation
    total = 0
    with Image.open(out) as gif:
        for k in range(gif.n_frames):
            gif.seek(k)
            total += gif.info['duration']
    assert abs(total - 1000.0 * simulated / speed) <= animation.GIF_DELAY_UNIT_MS
    capsys.readouterr()


def test_a_gif_faster_than_viewers_play_is_refused(run_file, tmp_path, capsys):
    out = tmp_path / 'run.gif'
    assert cli_main(['animate', run_file, '-o', str(out), '--fps', '60']) == 2
    err = capsys.readouterr().err
    assert 'at most 50 frames/s' in err and '.mp4' in err
    assert not out.exists()


@pytest.fixture
def scene(run_file):
    """The animation's figure for a recording shown on the multi-scale example cell."""
    from matplotlib import pyplot as plt
    data = load_frames(run_file, fps=5.0, speed=1.0)
    data = dataclasses.replace(data, cell=_cell('multiscale.yaml'))
    scene = animation._Scene(data, view=None, width=None)
    scene.update(data.frames[len(data.frames) // 2])
    yield scene
    plt.close(scene.fig)


def test_the_cell_strip_is_tall_enough_and_to_scale(scene):
    scene.fig.canvas.draw()
    box = scene.ax.get_window_extent()
    assert box.height >= animation.MIN_SCENE_HEIGHT * scene.fig.dpi - 1.0
    x0, x1 = scene.ax.get_xlim()
    y0, y1 = scene.ax.get_ylim()
    # equal scales: metres per pixel alike in x and y
    assert (x1 - x0) / box.width == pytest.approx((y1 - y0) / box.height, rel=0.02)
    cx0, cx1, cy0, cy1 = cell_drawing.view_limits(scene.data.cell, margin=0.0)
    assert x0 <= cx0 and cx1 <= x1 and y0 <= cy0 and cy1 <= y1   # the whole cell shown
    _texts_inside_figure(scene.fig)


def test_the_density_colour_bar_matches_the_plot(scene, run_file):
    from matplotlib import pyplot as plt
    image = next(iter(scene.density_images.values()))
    bar = image.colorbar
    assert bar is not None and 'parts/m²' in bar.ax.get_ylabel()
    assert image.get_cmap().name == style.DENSITY_CMAP
    rho_max = scene.data.cell.rho_max
    assert image.norm.vmin == 0.0 and image.norm.vmax == pytest.approx(rho_max)
    data = series_mod.load(run_file, density_times=[0.5, 1.0])
    fig = plot_verb.density_figure(data.density, 'run', rho_max)
    try:
        plotted = [im for ax in fig.axes for im in ax.images]
        assert plotted and all(im.get_cmap().name == style.DENSITY_CMAP for im in plotted)
        assert all(im.norm.vmin == 0.0 and im.norm.vmax == pytest.approx(rho_max)
                   for im in plotted)
        labels = [ax.get_ylabel() for ax in fig.axes]
        assert style.DENSITY_LABEL in labels
    finally:
        plt.close(fig)


def test_commanded_and_actual_belt_speed_are_both_visible(scene):
    ax_v = scene.fig.axes[-1]
    assert 'belt speeds' in ax_v.get_title()
    lines = [line for line in ax_v.get_lines() if len(line.get_xdata()) > 2]
    actual = [line for line in lines if line.get_linestyle() == '-']
    commanded = [line for line in lines if line.get_linestyle() == '--']
    assert len(actual) == len(commanded) == len(scene.data.belts.names) == 2
    for a, c in zip(actual, commanded):
        assert a.get_color() == c.get_color()
        assert c.get_zorder() > a.get_zorder()          # commanded drawn on top ...
        assert a.get_linewidth() > 2.5 * c.get_linewidth()   # ... inside a wider band
    legend = [t.get_text() for t in ax_v.get_legend().get_texts()]
    assert {'infeed', 'main', 'actual', 'commanded'} <= set(legend)


# --- figures of a recording -------------------------------------------------------------

def test_density_figure_keeps_its_labels_inside(run_file):
    from matplotlib import pyplot as plt
    data = series_mod.load(run_file, density_times=[0.0, 1.0, 5.0, 9.0])
    fig = plot_verb.density_figure(data.density, 'run', None)
    try:
        # 5 s and 9 s are past the end: the last grid is drawn once
        assert len([ax for ax in fig.axes if ax.images]) == 3
        _texts_inside_figure(fig)
    finally:
        plt.close(fig)


def test_plot_draws_the_cell_under_the_paths_and_skips_empty_figures(cell_run, tmp_path,
                                                                      capsys):
    out = tmp_path / 'figs'
    assert plot_verb.main([cell_run, '-o', str(out)]) == 0
    captured = capsys.readouterr()
    names = sorted(p.name for p in out.iterdir())
    assert names == ['belt_speeds.png', 'trajectories_x.png', 'trajectories_xy.png']
    assert 'skipped actuators.png: the cell has no actuators' in captured.err
    assert 'skipped density.png' in captured.err and 'skipped light_barriers.png' in captured.err
    assert 'Warning' not in captured.err
    assert all(line.endswith('.png') for line in captured.out.split())
    with Image.open(out / 'trajectories_xy.png') as image:
        pixels = np.asarray(image.convert('RGB')).reshape(-1, 3)
    belt = np.all(pixels == (0xd9, 0xd9, 0xd9), axis=1).mean()
    assert belt > 0.05   # the belt surface of the cell lies under the paths
