"""Pictures: a cell's layout (``plot CELL.yaml``) and a recording's animation (``animate``)."""

import os

import numpy as np
import pytest
import yaml

from conveyor_twin.cell import default_cell_text, load_cell
from conveyor_twin.cli import main as cli_main
from conveyor_twin.cli import plot as plot_verb
from conveyor_twin.viz import animation, cell_drawing
from conveyor_twin.viz.frames import frame_times, load_frames

from ..record.synthetic import belt_clock, conveyor_run

Image = pytest.importorskip('PIL.Image')


@pytest.fixture(scope='module')
def run_file(tmp_path_factory) -> str:
    path = str(tmp_path_factory.mktemp('anim') / 'run.mcap')
    conveyor_run(path, seconds=2.0, parts=6)
    return path


def _colours(path: str) -> int:
    with Image.open(path) as image:
        pixels = np.asarray(image.convert('RGB')).reshape(-1, 3)
    return len(np.unique(pixels, axis=0))


def test_plot_of_the_default_cell_writes_a_png_to_scale(tmp_path, capsys):
    out = tmp_path / 'cell.png'
    assert cli_main(['plot', 'default', '-o', str(out), '--dpi', '50', '--width', '12']) == 0
    assert capsys.readouterr().out.strip() == str(out)
    cell = load_cell()
    width, height = cell_drawing.figure_size(cell_drawing.view_limits(cell), 12.0)
    with Image.open(out) as image:
        assert image.format == 'PNG'
        # cropped to what is drawn: about the figure's width, a 6.4 m x 1 m view's height
        assert 0.85 * width * 50 <= image.size[0] <= width * 50 + 10
        assert 0.1 < image.size[1] / image.size[0] < 0.4
    assert _colours(str(out)) > 50  # belts, obstacles, labels, beams: not a blank canvas


def test_cell_view_holds_every_element():
    cell = load_cell()
    x0, x1, y0, y1 = cell_drawing.view_limits(cell, margin=0.0)
    # walls (half their thickness beyond x = 0), the exit sink, the reject bin below the belt,
    # the pusher's retracted paddle beyond the wall
    assert (x0, x1) == pytest.approx((-0.005, 6.3))
    assert y0 == pytest.approx(-0.6)
    pusher = cell.actuators[cell.actuator_index('pusher')]
    top = max(y for _, y in cell_drawing.actuator_outline(pusher, 0.0))
    assert top == pytest.approx(0.285) and y1 == pytest.approx(0.3)  # the exit sink's top
    # at full stroke the paddle's centre is 0.5 m along its axis (-y)
    corners = cell_drawing.actuator_outline(pusher, 0.5)
    assert np.mean([y for _, y in corners]) == pytest.approx(0.275 - 0.5)


def test_plot_of_a_cell_file_and_its_errors(tmp_path, capsys):
    doc = yaml.safe_load(default_cell_text())
    doc['zones'][0]['policy'] = 'auto'
    good = tmp_path / 'auto.yaml'
    good.write_text(yaml.safe_dump(doc))
    assert plot_verb.main([str(good), '-o', str(tmp_path / 'auto.png'), '--dpi', '40']) == 0
    assert (tmp_path / 'auto.png').stat().st_size > 0
    doc['belts'][0]['width'] = -1.0
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump(doc))
    capsys.readouterr()
    assert plot_verb.main([str(bad), '-o', str(tmp_path / 'bad.png')]) == 1
    err = capsys.readouterr().err
    assert 'invalid cell' in err and 'width' in err and 'bad.yaml' in err
    assert not (tmp_path / 'bad.png').exists()
    assert plot_verb.main([str(good), '-o', str(tmp_path / 'cell.jpg')]) == 2
    assert '.png' in capsys.readouterr().err


def test_validate_suggests_the_plot(capsys):
    assert cli_main(['validate']) == 0
    assert 'conveyor-twin plot default -o cell.png' in capsys.readouterr().out


def test_frame_times_follow_speed_and_rate():
    times = frame_times(0.0, 2.0, fps=10.0, speed=2.0)
    assert len(times) == 11 and times[1] == pytest.approx(0.2) and times[-1] == pytest.approx(2)


def test_frames_show_the_latest_state(run_file):
    data = load_frames(run_file, fps=5.0, speed=1.0)
    assert len(data.frames) == 10  # 0 .. 1.8 s every 0.2 s (the last message is at 1.999 s)
    assert data.cell is None  # the synthetic recording's cell.yaml is no valid cell
    frame = data.frames[5]  # t = 1.0 s: parts entered every 0.25 s, x = 0.5 m/s * age
    assert frame.t == pytest.approx(1.0)
    assert frame.parts.stamp_ns == 1_000_000_000
    assert np.sort(frame.parts.x) == pytest.approx([0.0, 0.125, 0.25, 0.375, 0.5], abs=1e-3)
    assert frame.density['buffer'].stamp_ns == 1_000_000_000
    assert data.barriers.names == ('lb_mid',) and data.belts.names == ('infeed', 'main')
    # the series are sampled four times per frame
    assert len(data.barriers.t) == pytest.approx(4 * 5 * 2, abs=1)


def test_animate_writes_a_gif_with_the_expected_frames(run_file, tmp_path, capsys):
    out = tmp_path / 'run.gif'
    assert cli_main(['animate', run_file, '-o', str(out), '--fps', '2', '--speed', '0.5',
                     '--dpi', '30', '--width', '6']) == 0
    captured = capsys.readouterr()
    assert '8/8 frames' in captured.err  # the progress bar reached the end
    assert '8 frames' in captured.out
    with Image.open(out) as gif:
        assert gif.format == 'GIF'
        assert gif.n_frames == 8  # 0 .. 1.75 s every 0.25 s of simulation
        assert gif.info['duration'] == 500  # ms per frame at 2 frames/s
    assert not [p for p in os.listdir(tmp_path) if p.startswith('.animate-')]


def test_animate_a_window_of_the_recording(run_file, tmp_path, capsys):
    out = tmp_path / 'window.gif'
    assert cli_main(['animate', run_file, '-o', str(out), '--fps', '2', '--speed', '1',
                     '--start', '0.5', '--end', '1.5', '--view', '0,1.2', '--quiet',
                     '--dpi', '30', '--width', '6']) == 0
    assert capsys.readouterr().err == ''
    with Image.open(out) as gif:
        assert gif.n_frames == 3  # 0.5, 1.0, 1.5 s


def test_recording_without_parts_is_refused_and_output_untouched(tmp_path, capsys):
    path = str(tmp_path / 'belts.mcap')
    belt_clock(path, 0.2)
    out = tmp_path / 'run.gif'
    out.write_bytes(b'previous animation')
    assert cli_main(['animate', path, '-o', str(out)]) == 1
    err = capsys.readouterr().err
    assert 'no part states to animate' in err and 'belts.mcap' in err
    assert 'Traceback' not in err
    assert out.read_bytes() == b'previous animation'
    assert cli_main(['animate', str(tmp_path / 'missing.mcap'), '-o', str(out)]) == 1
    assert out.read_bytes() == b'previous animation'


def test_mp4_without_ffmpeg_says_how_to_install_it(run_file, tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(animation.shutil, 'which', lambda name: None)
    out = tmp_path / 'run.mp4'
    assert cli_main(['animate', run_file, '-o', str(out)]) == 2
    err = capsys.readouterr().err
    assert 'ffmpeg' in err and 'apt-get install ffmpeg' in err and 'Traceback' not in err
    assert not out.exists()
    assert cli_main(['animate', run_file, '-o', str(tmp_path / 'run.avi')]) == 2
    assert '.gif or .mp4' in capsys.readouterr().err
    assert cli_main(['animate', run_file, '-o', str(tmp_path / 'no' / 'run.gif')]) == 2
    assert 'does not exist' in capsys.readouterr().err
