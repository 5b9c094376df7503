"""When a plant cell started with ``--cell`` ends: once it and every cell it shares a link with
are done. A cell of the plant it shares no link with (never started here, or whose reports
cannot reach it) does not keep it waiting; a done cell whose neighbour is not done says which
one it waits for."""

import json
from pathlib import Path
import subprocess
import sys

import pytest

from conveyor_twin.testing.ros_env import wait_for

RES = Path(__file__).resolve().parents[1] / 'resources' / 'plant'
DURATION = '1.5'        # s simulated
STEPS = 1500
TIMEOUT = 240.0         # s, a bound for a loaded machine, not a speed requirement

pytestmark = pytest.mark.ros


def chain_with_spare(folder: Path) -> Path:
    """The test chain (feeder -> first -> second) and a fourth cell, ``spare``, that shares
    no link with them."""
    path = folder / 'plant.yaml'
    path.write_text(f'''plant: {{name: chain, seed: 3}}
cells:
  - {{name: feeder, file: {RES / 'feeder.yaml'}}}
  - {{name: first, file: {RES / 'relay.yaml'}, placement: {{x: 0.5}}}}
  - {{name: second, file: {RES / 'relay.yaml'}, placement: {{x: 1.0}}}}
  - {{name: spare, file: {RES / 'feeder.yaml'}, placement: {{x: 3.0}}}}
links:
  - {{name: feed_first, from: {{cell: feeder, sink: exit}}, to: {{cell: first, belt: main}},
     delay_steps: 40, capacity: 4}}
  - {{name: first_second, from: {{cell: first, sink: exit}}, to: {{cell: second, belt: main}},
     delay: 0.03}}
''')
    return path


def start_cell(processes, plant: Path, cell: str, folder: Path,
               duration: str = DURATION) -> subprocess.Popen:
    out = open(folder / f'{cell}.json', 'w')
    err = open(folder / f'{cell}.err', 'w')
    return processes.start([sys.executable, '-m', 'conveyor_twin.cli', 'plant', str(plant),
                            '--cell', cell, '--no-streams', '--mode', 'fast', '--duration',
                            duration, '--run-id', '1'], stdout=out, stderr=err)


def summary(folder: Path, cell: str) -> dict:
    return json.loads((folder / f'{cell}.json').read_text().strip().splitlines()[-1])


def test_cells_end_without_a_cell_they_share_no_link_with(ros_processes, tmp_path):
    plant = chain_with_spare(tmp_path)
    procs = {c: start_cell(ros_processes, plant, c, tmp_path)
             for c in ('feeder', 'first', 'second')}   # 'spare' never runs
    for cell, proc in procs.items():   # they waited for 'spare' forever before
        assert proc.wait(timeout=TIMEOUT) == 0, (tmp_path / f'{cell}.err').read_text()
        assert summary(tmp_path, cell)['step'] == STEPS


def test_a_done_cell_says_which_neighbour_it_waits_for(ros_processes, tmp_path):
    plant = chain_with_spare(tmp_path)
    feeder = start_cell(ros_processes, plant, 'feeder', tmp_path, duration='0')  # no end
    first = start_cell(ros_processes, plant, 'first', tmp_path)
    second = start_cell(ros_processes, plant, 'second', tmp_path)
    # 'second' ends: its one neighbour, 'first', is done (its exit heard the final batch)
    assert second.wait(timeout=TIMEOUT) == 0, (tmp_path / 'second.err').read_text()
    said = ("cell 'first' is done at step 1500; waiting for the done reports of 'feeder' "
            "(last report: step ")
    assert wait_for(lambda: said in (tmp_path / 'first.err').read_text(), TIMEOUT), \
        (tmp_path / 'first.err').read_text()
    assert first.poll() is None and feeder.poll() is None
    ros_processes.stop_all()
    err = (tmp_path / 'first.err').read_text()
    assert err.count('plant: ' + said) == 1 and 'plant: stopped: ' + said in err, err
    assert summary(tmp_path, 'first')['step'] == STEPS
