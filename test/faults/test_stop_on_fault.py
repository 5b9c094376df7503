"""examples/stop_on_fault.py against a lockstep twin with injected faults (public API only).

The timed tests attach the watchdog in the test process (``add_node``): the harness lets it
react at every chunk, so its reaction time is exact whatever the load. As its own process it
reads the 1 kHz ``light_barriers`` stream at its own pace; the last test runs it that way.
"""

import importlib.util
from pathlib import Path
import sys

import pytest
from rclpy.parameter import Parameter

from conveyor_twin.testing import FaultRejectedError, quiet_cell

pytestmark = pytest.mark.ros
EXAMPLE = Path(__file__).resolve().parents[2] / 'examples' / 'stop_on_fault.py'
CHUNK = 5          # steps per step call: the controller reacts within this many
MS = 1_000_000     # [ns]


def _attach(twin) -> None:
    spec = importlib.util.spec_from_file_location('stop_on_fault', EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    twin.add_node(module.StopOnFault(context=twin.context, parameter_overrides=[
        Parameter('barrier', value='lb_exit'), Parameter('timeout', value=0.5)]))


def _start(twin) -> None:
    twin.start_controller([sys.executable, str(EXAMPLE), '--ros-args', '-p', 'barrier:=lb_exit',
                           '-p', 'timeout:=0.5'])
    twin.wait_for_node('stop_on_fault', subscribes=['light_barriers'],
                       publishes=['belt_command'])


def _stops(twin) -> list:
    return [r for r in twin.command_log() if r.target == 'main' and r.value == 0.0]


def test_a_stuck_barrier_stops_the_belt_after_the_timeout(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), seed=3, chunk=CHUNK)
    _attach(twin)
    twin.step(200)
    fault = twin.inject_fault('barrier_stuck_blocked', 'lb_exit')
    twin.step(1)
    assert twin.active_faults()[fault].kind == 'barrier_stuck_blocked'
    stuck_ns = twin.time_ns
    assert twin.barrier('lb_exit').blocked
    twin.step_until(lambda: _stops(twin), max_steps=1000, what='the watchdog stops the belt')
    twin.step(1)  # the command takes effect at the next step
    stop = [b for b in twin.belt_history('main') if b.commanded == 0.0][0]
    assert 500 * MS <= stop.stamp_ns - stuck_ns <= (500 + 2 * CHUNK + 1) * MS
    twin.clear_fault(fault)
    twin.step(1)
    assert twin.active_faults() == {} and not twin.barrier('lb_exit').blocked
    with pytest.raises(FaultRejectedError, match='no active fault'):
        twin.clear_fault(fault)
    with pytest.raises(FaultRejectedError, match="light barrier 'lb_nowhere' is unknown"):
        twin.inject_fault('barrier_stuck_free', 'lb_nowhere')


def test_a_jammed_part_in_the_beam_stops_the_belt(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), seed=3, chunk=CHUNK)
    _attach(twin)
    [part] = twin.spawn('spacer', [5.3], [0.0])  # upstream of lb_exit
    twin.step_until(lambda: twin.barrier('lb_exit').blocked, max_steps=5000,
                    what='the part reaches lb_exit')
    twin.inject_fault('part_jam', str(part))
    twin.step_until(lambda: _stops(twin), max_steps=1000, what='the watchdog stops the belt')
    assert twin.barrier('lb_exit').blocked


def test_no_fault_no_stop(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), seed=3, chunk=CHUNK)
    _start(twin)
    twin.spawn('spacer', [5.3, 5.0], [0.0, 0.0])
    twin.step(3000)
    assert len(twin.edges(name='lb_exit')) >= 2 and not _stops(twin)
