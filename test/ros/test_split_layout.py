"""The split layout (three processes, lockstep) and determinism across layouts and reruns.

The same cell, seed and command sequence must give bit-identical streams whether the nodes are
composed in one process or split over three, and from one run to the next.
"""

import sys

from conveyor_twin_msgs.msg import ActuatorCommand, BeltCommand
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.stages import MacroStage
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.ros.compose import ComposedTwin
from conveyor_twin.ros.split import _ros_args
from conveyor_twin.wire import cdr
from test.ros.test_node_parameters import check_parameters as check_node_parameters, NODES
from test.ros.twin_driver import Driver

pytestmark = pytest.mark.ros
SEED = 7
# The default cell's feeder brings parts in from the start; a part placed just before the
# infeed barrier gives edges early; belt and pusher commands change the motion on the way.
SEQUENCE = (
    ('spawn', ('spacer', [1.9], [0.05], [0.0])),
    ('step', 300),
    ('command', BeltCommand(belt='main', speed=1.0)),
    ('step', 300),
    ('command', ActuatorCommand(actuator='pusher', position=0.3)),
    ('step', 250),
    ('command', BeltCommand(belt='main', speed=0.2)),
    ('step', 250),
)
STEPS = sum(arg for kind, arg in SEQUENCE if kind == 'step')


def _density_per_step(cell) -> int:
    return len(MacroStage(cell).grids)


def start_split(ros_processes, tmp_path, tag: str):
    """Start micro, macro and coordinator processes in lockstep; return them."""
    args = _ros_args('', SEED, 'lockstep', 0.0, None, 0.0)
    procs = []
    for module in ('conveyor_twin.ros.micro_node', 'conveyor_twin.ros.macro_node',
                   'conveyor_twin.ros.split'):
        log = open(tmp_path / f'{tag}_{module.rsplit(".", 1)[1]}.log', 'w')
        procs.append(ros_processes.start([sys.executable, '-m', module] + args,
                                         stdout=log, stderr=log))
        log.close()
    return procs


def _logs(tmp_path) -> str:
    return '\n'.join(f'--- {p.name}\n{p.read_text()[-2000:]}' for p in tmp_path.glob('*.log'))


def run_composed(context, name: str):
    cell = load_cell()
    twin = ComposedTwin(cell, seed=SEED, mode=TimeMode.LOCKSTEP, context=context,
                        markers_rate=0.0)
    twin.start()
    driver = Driver(context, density_per_step=_density_per_step(cell), name=name)
    try:
        assert driver.wait_connected(), 'composed twin not discovered'
        driver.run(SEQUENCE)
        return driver.digests(), driver.counts(), driver
    finally:
        driver.close()
        twin.stop()


def run_split(context, ros_processes, tmp_path, tag: str, check_parameters: bool = False):
    start_split(ros_processes, tmp_path, tag)
    driver = Driver(context, density_per_step=_density_per_step(load_cell()), name='probe_' + tag)
    try:
        assert driver.wait_connected(), 'split twin not discovered\n' + _logs(tmp_path)
        driver.run(SEQUENCE)
        if check_parameters:  # each process's real node declares the parameters
            for node in NODES:
                check_node_parameters(driver, node, seed=SEED, mode='lockstep',
                                      markers_rate=0.0)
        return driver.digests(), driver.counts(), driver
    finally:
        driver.close()
        ros_processes.stop_all()


def _assert_consecutive(driver: Driver) -> None:
    received = driver.probe.received
    parts = [cdr.decode_part_states(d).step for d in received['parts']]
    assert parts == list(range(1, STEPS + 1))
    barriers = [cdr.decode_light_barrier_states(d)[2] for d in received['light_barriers']]
    assert barriers == list(range(1, STEPS + 1))
    for topic in ('belt_states', 'actuator_states'):
        stamps = [int.from_bytes(d[4:8], 'little') * 10**9 + int.from_bytes(d[8:12], 'little')
                  for d in received[topic]]
        assert stamps == [k * 1_000_000 for k in range(1, STEPS + 1)]


def test_split_streams_are_consecutive_and_identical_to_composed_and_reruns(
        ros_context, ros_processes, tmp_path):
    composed, composed_counts, composed_driver = run_composed(ros_context, 'probe_c1')
    _assert_consecutive(composed_driver)
    last = cdr.decode_part_states(composed_driver.probe.received['parts'][-1])
    assert len(last.id) >= 10, 'the hash should cover moving parts'
    assert composed_counts['light_barrier_edges'] >= 2, 'the hash should cover edges'
    rerun, _, _ = run_composed(ros_context, 'probe_c2')
    assert rerun == composed

    split, split_counts, split_driver = run_split(ros_context, ros_processes, tmp_path, 's1',
                                                        check_parameters=True)
    _assert_consecutive(split_driver)
    # /clock is best effort, keep-last 1 (the ROS convention): it may drop, so it is not hashed
    split_counts.pop('/clock')
    composed_counts.pop('/clock')
    assert split_counts == composed_counts
    assert split == composed, _logs(tmp_path)
    split_rerun, _, _ = run_split(ros_context, ros_processes, tmp_path, 's2')
    assert split_rerun == composed


def test_split_refuses_a_cell_with_macro_zones_rather_than_run_it_uncoupled(tmp_path):
    import subprocess

    import yaml

    from conveyor_twin.cell import default_cell_text
    from conveyor_twin.ros.split import refusal
    from test.ros_env import ros_subprocess_env
    assert refusal(load_cell()) is None
    doc = yaml.safe_load(default_cell_text())
    doc['zones'][0]['policy'] = 'auto'
    path = tmp_path / 'auto_cell.yaml'
    path.write_text(yaml.safe_dump(doc))
    cell = load_cell(str(path))
    assert "'belt' (auto)" in refusal(cell)
    for argv in (['-m', 'conveyor_twin.cli', 'run', '--split', '--cell', str(path),
                  '--duration', '0.01'],
                 ['-m', 'conveyor_twin.ros.split', '--ros-args', '-p', f'cell_file:={path}']):
        done = subprocess.run([sys.executable] + argv, env=ros_subprocess_env(),
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 2, done.stderr
        assert 'does not couple the micro and macro scales' in done.stderr
        assert "'belt' (auto)" in done.stderr and 'without --split' in done.stderr
