"""The testing harness under faults and failures: silenced streams, bad arguments, its own
traces (environment, logs) and the failures of the twin's threads and processes."""

import math
import os
import signal
import shutil
import sys

import pytest

from conveyor_twin.faults.model import OUTAGE_STREAMS
from conveyor_twin.health import BackgroundFailure
from conveyor_twin.testing import LockstepTwin, quiet_cell, TwinTimeoutError

pytestmark = pytest.mark.ros

LAYOUTS = ['composed', pytest.param('split', marks=pytest.mark.slow)]


def _edge_total(twin: LockstepTwin) -> int:
    return sum(b.edge_count for b in twin.barriers().values())


@pytest.mark.parametrize('layout', LAYOUTS)
def test_step_and_reset_do_not_wait_for_silenced_streams(conveyor_twin_factory, layout):
    twin = conveyor_twin_factory(quiet_cell() if layout == 'composed' else None,
                                 layout=layout, chunk=10)
    twin.spawn('spacer', [1.8], [0.0])
    for stream in OUTAGE_STREAMS:
        fault = twin.inject_fault('stream_outage', stream)
        twin.step(25)
        assert twin.active_faults()[fault].target == stream
        twin.clear_fault(fault)
        twin.step(5)
    # an outage that ends within a chunk
    twin.inject_fault('stream_outage', 'parts', duration=0.0035)
    twin.step(20)
    # edges counted while their stream is silent are never sent: neither step nor reset
    # waits for them
    twin.inject_fault('stream_outage', 'light_barrier_edges')
    before, edges = _edge_total(twin), len(twin.edges())
    twin.step_until(lambda: _edge_total(twin) > before, max_steps=3000,
                    what='the part crosses lb_infeed while edges are silenced')
    twin.step(10)
    assert len(twin.edges()) == edges
    twin.reset()
    assert twin.step(10) == 10
    assert twin.active_faults() == {}


def test_a_timeout_names_what_it_waited_for_and_the_active_outages(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), timeout=2.0)
    twin.inject_fault('stream_outage', 'parts')
    twin.step(2)
    twin._driver.probe.received['belt_states'].clear()  # as if the stream never came
    with pytest.raises(TwinTimeoutError) as raised:
        twin._driver.wait(lambda: False, 'belt_states of step 2')
    text = str(raised.value)
    assert 'belt_states of step 2: not within 2 s' in text
    assert 'active stream outages: parts (fault 1)' in text


def test_numeric_arguments_are_checked(conveyor_twin_factory):
    with pytest.raises(ValueError, match=r'chunk = 0 is not allowed: it must be an integer in'):
        LockstepTwin(chunk=0)
    with pytest.raises(ValueError, match=r'timeout = nan is not allowed'):
        LockstepTwin(timeout=math.nan)
    with pytest.raises(ValueError, match=r'seed = -1 is not allowed'):
        LockstepTwin(seed=-1)
    twin = conveyor_twin_factory(quiet_cell())
    assert twin.step_for(0) == 0 and twin.step(0) == 0   # zero steps: no step
    assert twin.step_for(0.0004) == 0                      # less than half a step
    for bad in (-1, -0.001, math.nan, math.inf, '1', None, True):
        with pytest.raises(ValueError, match=r'step_for\(seconds\): seconds = .* is not '
                                             r'allowed: it must be a finite number of seconds'):
            twin.step_for(bad)
    for bad in (-1, 1.5, '2', True):
        with pytest.raises(ValueError, match=r'step\(n\): n = .* must be an integer >= 0'):
            twin.step(bad)
    with pytest.raises(ValueError, match=r'max_steps = 0 is not allowed'):
        twin.step_until(lambda: True, max_steps=0)
    with pytest.raises(ValueError, match=r'wait_until: timeout = -1 is not allowed'):
        twin.wait_until(lambda: True, timeout=-1)
    with pytest.raises(ValueError, match=r"speed = '1.5' is not allowed: it must be a real"):
        twin.set_belt('main', '1.5')
    with pytest.raises(ValueError, match=r'x\[1\] = .* is not allowed'):
        twin.spawn('spacer', [1.0, 'a'], [0.0, 0.0])
    with pytest.raises(ValueError, match=r'fault_id = -2 is not allowed'):
        twin.clear_fault(-2)
    with pytest.raises(ValueError, match=r"parameter probability = 'x' is not allowed"):
        twin.inject_fault('command_drop', 'belt_command', probability='x')
    assert twin.step_for(0.01) == 10
    assert not twin.set_belt('main', math.nan, check=False).accepted  # the twin judges it


def test_the_process_environment_is_left_alone(monkeypatch):
    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    monkeypatch.setenv('ROS_LOCALHOST_ONLY', '0')
    before = dict(os.environ)
    with LockstepTwin(quiet_cell()) as twin:
        assert dict(os.environ) == before
        twin.step(2)
        twin.start_controller([sys.executable, '-c', 'import os; print('
                               'os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"], '
                               'os.environ["ROS_DOMAIN_ID"])'])
        twin.wait_until(lambda: twin.controller_output().strip(), what='the child prints')
        assert twin.controller_output().split() == ['LOCALHOST', str(twin.domain_id)]
        assert twin.context.get_domain_id() == twin.domain_id
    assert dict(os.environ) == before


@pytest.mark.slow
def test_the_split_layout_leaves_no_logs_behind():
    with LockstepTwin(layout='split') as twin:
        twin.step(3)
        log_dir = twin.log_dir
        assert sorted(p.name for p in log_dir.iterdir()) == [
            'macro_node.log', 'micro_node.log', 'split.log']
    assert not log_dir.exists()


def test_a_failed_background_thread_fails_the_next_call(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell())
    twin.step(1)
    twin.composed.twin.health.report('recorder writer', RuntimeError('disk full'))
    for call in (lambda: twin.step(1), twin.reset, lambda: twin.set_belt('main', 0.1),
                 lambda: twin.spawn('spacer', [1.0], [0.0])):
        with pytest.raises(BackgroundFailure, match=r"recorder writer: RuntimeError\('disk "
                                                    r"full'\)"):
            call()


def test_a_controller_process_that_dies_fails_the_next_call(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell())
    process = twin.start_controller([sys.executable, '-c',
                                     'print("giving up"); raise SystemExit(3)'])
    process.wait(timeout=60)
    with pytest.raises(BackgroundFailure) as raised:
        twin.step(1)
    failure, = raised.value.failures
    assert failure.name.startswith('controller process 0') and 'exited with code 3' in \
        failure.error
    assert str(twin.log_dir) in str(raised.value)
    log_dir = twin.log_dir
    twin.close()
    assert 'giving up' in (log_dir / 'controller_0.log').read_text()  # kept: the twin failed
    shutil.rmtree(log_dir)


@pytest.mark.slow
def test_a_dead_split_process_is_named_with_its_exit_code_and_log(conveyor_twin_factory):
    twin = conveyor_twin_factory(layout='split')
    twin.step(2)
    micro = [c.proc for c in twin._running.split.children if c.name == 'micro_simulator'][0]
    os.kill(micro.pid, signal.SIGKILL)
    micro.wait(timeout=60)
    with pytest.raises(BackgroundFailure) as raised:
        twin.step(1)
    text = str(raised.value)
    assert 'micro_simulator process: exited with code -9' in text
    assert f'the twin\'s logs are kept in {twin.log_dir}' in text
    log_dir = twin.log_dir
    twin.close()
    assert (log_dir / 'micro_node.log').exists()
    shutil.rmtree(log_dir)


@pytest.mark.parametrize('layout', LAYOUTS)
def test_spawn_and_part_jam_are_checked_against_the_cell_and_its_parts(conveyor_twin_factory,
                                                                       layout):
    from conveyor_twin.testing import FaultRejectedError, ServiceError
    twin = conveyor_twin_factory(None, layout=layout, chunk=10)
    with pytest.raises(ServiceError) as raised:
        twin.spawn('spacer', [1.0, 4.5], [0.0, 0.9])
    assert ("part 1 (spacer) at x = 4.5 m, y = 0.9 m is not on a belt (allowed: a centre on "
            "belt 'main': x 0..6 m, y -0.25..0.25 m)") in str(raised.value)
    with pytest.raises(ServiceError, match="overlaps wall 'wall_right_in'"):
        twin.spawn('spacer', [1.0], [-0.248])
    [part] = twin.spawn('spacer', [1.0], [0.0])
    with pytest.raises(FaultRejectedError) as raised:
        twin.inject_fault('part_jam', str(int(part) + 1000))
    assert f"target '{int(part) + 1000}': no such part exists now" in str(raised.value)
    assert twin.active_faults() == {}
    fault = twin.inject_fault('part_jam', str(int(part)))
    twin.step(20)
    assert twin.active_faults()[fault].kind == 'part_jam'
    x = twin.part(int(part))['x']
    twin.step(50)
    assert twin.part(int(part))['x'] == x   # held


CONTROLLER = os.path.join(os.path.dirname(__file__), 'paced_controller.py')


def test_a_paced_controller_process_sees_its_command_in_time(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), chunk=5)
    twin.start_controller([sys.executable, CONTROLLER, '--ros-args', '-p', 'work:=0.002'],
                          pace='paced_watchdog')
    twin.wait_for_node('paced_watchdog', subscribes=['belt_states'],
                       publishes=['belt_command', 'lockstep_ack'])
    twin.step(150)
    output = twin.controller_output()
    assert 'applied' in output and 'TIMEOUT' not in output, output
    [record] = twin.command_log()
    assert (record.sender, record.sequence, record.value) == ('paced_watchdog', 1, 0.3)
    decided = int(output.split('decided at ')[1].split()[0]) // 1_000_000
    assert decided <= record.result.step <= decided + twin.chunk  # answered within a chunk
    assert twin.belt('main').commanded_speed == 0.3
    twin.reset()
    twin.step(10)  # acknowledgements of the run before the reset do not count
