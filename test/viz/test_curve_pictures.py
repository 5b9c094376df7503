"""Curved belts and transfer units in the pictures: ``plot`` (cell and recording) and
``animate`` draw them to scale, the transfer unit coloured up or down per frame."""

import math
from pathlib import Path

import numpy as np
import pytest

from conveyor_twin.cell import load_cell_text
from conveyor_twin.cli import main as cli_main
from conveyor_twin.cli import plot as plot_verb
from conveyor_twin.viz import animation, cell_drawing
from conveyor_twin.viz.frames import load_frames

from .curve_cell import CURVE_CELL, curve_run

Image = pytest.importorskip('PIL.Image')

EXAMPLES = Path(cell_drawing.__file__).resolve().parents[1] / 'cell' / 'examples'
#: The cells with a curved belt or a transfer unit: the test's own and the shipped examples.
CELLS = {'curve_test': CURVE_CELL}
CELLS.update({p.stem: p.read_text() for p in (EXAMPLES / 'l_line.yaml',
                                                EXAMPLES / 'transfer.yaml') if p.exists()})


def _polygon_area(points) -> float:
    p = np.asarray(points)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _belt_patches(ax):
    return [p for p in ax.patches
            if hasattr(p, 'get_xy') and p.get_zorder() == 0
            and np.allclose(p.get_facecolor()[:3], (0xd9 / 255,) * 3)]


def test_a_curved_belt_is_drawn_as_its_annulus_within_the_chord_error():
    from matplotlib import pyplot as plt
    cell = load_cell_text(CURVE_CELL)
    bend = cell.belts[1]
    c = bend.curve
    fig, ax = plt.subplots()
    try:
        cell_drawing.draw_static(ax, cell, labels=False)
        straight, curved = _belt_patches(ax)
        xy = curved.get_xy()[:-1]   # matplotlib repeats the first point
        assert straight.get_xy()[:-1] == pytest.approx(np.array(cell.belts[0].corners()))
        r = np.hypot(xy[:, 0] - c.centre[0], xy[:, 1] - c.centre[1])
        # every vertex on one of the arcs, every edge within the chord error of the annulus
        assert np.all(np.isclose(r, c.inner_radius) | np.isclose(r, c.outer_radius))
        mid = 0.5 * (xy + np.roll(xy, -1, axis=0))
        rm = np.hypot(mid[:, 0] - c.centre[0], mid[:, 1] - c.centre[1])
        assert np.all(rm >= c.inner_radius - cell_drawing.CHORD_ERROR - 1e-12)
        assert np.all(rm <= c.outer_radius + 1e-12)
        on_outer = np.isclose(r, c.outer_radius) & np.isclose(np.roll(r, -1), c.outer_radius)
        assert np.all(c.outer_radius - rm[on_outer] <= cell_drawing.CHORD_ERROR)
        # the area of the sector, short of it by at most the chord error along both arcs
        sector = 0.5 * abs(c.sweep) * (c.outer_radius ** 2 - c.inner_radius ** 2)
        area = abs(_polygon_area(xy))
        assert sector - cell_drawing.CHORD_ERROR * bend.length * 2.0 <= area <= sector + 1e-12
        x0, x1, y0, y1 = cell_drawing.view_limits(cell, margin=0.0)
        bx0, by0, bx1, by1 = bend.bounding_box()
        assert x0 <= bx0 and bx1 <= x1 and y0 <= by0 and by1 <= y1
    finally:
        plt.close(fig)


def test_the_arrow_of_a_curved_belt_lies_on_it_and_points_downstream():
    cell = load_cell_text(CURVE_CELL)
    bend = cell.belts[1]
    arrow, anchor = cell_drawing.curve_arrow(bend)
    assert all(bend.contains(p) for p in arrow) and bend.contains(anchor)
    n = len(arrow)
    tail = bend.curve.angle_along(((arrow[0][0] + arrow[-1][0]) / 2,
                                   (arrow[0][1] + arrow[-1][1]) / 2))
    tip = bend.curve.angle_along(arrow[(n - 1) // 2])
    assert 0.0 < tail < tip < abs(bend.curve.sweep)
    # as long as a straight belt's arrow: a quarter of the length or three widths
    assert (tip - tail) * bend.curve.centre_radius == pytest.approx(
        min(0.25 * bend.length, 3 * bend.width))


def test_a_transfer_unit_shows_whether_it_carries():
    cell = load_cell_text(CURVE_CELL)
    lift = cell.actuators[0]
    assert lift.kind == 'transfer'
    assert cell_drawing.actuator_face(lift, 0.0) == cell_drawing.TRANSFER_DOWN
    assert cell_drawing.actuator_face(lift, lift.engage_height) == cell_drawing.TRANSFER_UP
    outline = np.array(cell_drawing.actuator_outline(lift, lift.position_range[1]))
    # the footprint: length along the axis, width across, centred at the base
    assert outline.mean(axis=0) == pytest.approx(lift.base)
    assert np.ptp(outline[:, 1]) == pytest.approx(lift.length)
    assert np.ptp(outline[:, 0]) == pytest.approx(lift.width)


@pytest.mark.parametrize('name', sorted(CELLS))
def test_plot_of_the_cell_names_every_element(name, tmp_path, capsys):
    path = tmp_path / f'{name}.yaml'
    path.write_text(CELLS[name])
    out = tmp_path / 'cell.png'
    assert cli_main(['plot', str(path), '-o', str(out), '--dpi', '40']) == 0
    assert capsys.readouterr().out.strip() == str(out)
    with Image.open(out) as image:
        assert image.format == 'PNG'


@pytest.fixture(scope='module', params=sorted(CELLS))
def recorded(request, tmp_path_factory):
    name = request.param
    path = str(tmp_path_factory.mktemp(name) / 'run.mcap')
    return name, curve_run(path, CELLS[name])


def test_plot_draws_the_recording_over_the_curved_cell(recorded, tmp_path, capsys):
    _, run = recorded
    out = tmp_path / 'figs'
    assert plot_verb.main([run, '-o', str(out)]) == 0
    captured = capsys.readouterr()
    assert 'Warning' not in captured.err
    names = {p.name for p in out.iterdir()}
    assert {'trajectories_xy.png', 'belt_speeds.png'} <= names


def test_animate_shows_the_transfer_unit_up_and_down(recorded, tmp_path, capsys):
    from matplotlib import pyplot as plt
    name, run = recorded
    out = tmp_path / 'run.gif'
    assert cli_main(['animate', run, '-o', str(out), '--fps', '5', '--quiet', '--dpi', '30',
                     '--width', '6']) == 0
    assert 'Warning' not in capsys.readouterr().err
    data = load_frames(run, fps=5.0, speed=1.0)
    transfers = [k for k, a in enumerate(data.cell.actuators) if a.kind == 'transfer']
    scene = animation._Scene(data, view=None, width=None)
    try:
        for frame, face in ((data.frames[0], cell_drawing.TRANSFER_DOWN),
                            (data.frames[-1], cell_drawing.TRANSFER_UP)):
            scene.update(frame)
            for k in transfers:
                from matplotlib.colors import to_rgba
                assert scene.actuator_patches[k].get_facecolor() == to_rgba(face), name
    finally:
        plt.close(scene.fig)
    x0, x1 = scene.ax.get_xlim()
    bx0, _, bx1, _ = data.cell.bounds
    assert x0 <= bx0 and bx1 <= x1
    assert math.isfinite(x0)
