"""Faults over ROS: the services, the latched stream, diagnostics, both layouts bit-identical
(timed and triggered faults), the CLI's checks, recording and re-simulation."""

import subprocess
import sys

import pytest

from conveyor_twin.record.resimulate import resimulate
from conveyor_twin.testing import LockstepTwin, quiet_cell
from conveyor_twin.wire.decoders import decode_fault_state

pytestmark = pytest.mark.ros
SCENARIO = '''
name: timed faults of every stage
faults:
  - {kind: belt_slip, target: main, params: {factor: 0.6}, at: {step: 300}, duration: 0.4}
  - {kind: belt_speed_noise, target: main, params: {sigma: 0.02}, at: {time: 0.9}}
  - {kind: actuator_offset, target: pusher, params: {offset: 0.01}, at: {step: 50}}
  - {kind: barrier_chatter, target: lb_infeed, params: {frequency: 25}, at: {step: 200},
     duration: 0.3}
  - {kind: barrier_drop_edges, target: lb_after_deflector, params: {probability: 0.5},
     at: {step: 1}}
  - {kind: source_surge, target: feeder, params: {factor: 2.0}, at: {step: 100}}
  - {kind: parts_vanish, params: {x0: 2.4, y0: -0.3, x1: 2.6, y1: 0.3}, at: {step: 900}}
  - {kind: stream_outage, target: belt_states, at: {step: 700}, duration: 0.05}
  - {kind: belt_delay_commands, target: main, params: {delay: 0.1},
     at: {after_edges: {barrier: lb_infeed, count: 1}}}
  - {kind: barrier_stuck_free, target: lb_exit, at: {zone_parts_above: {zone: belt, count: 10}}}
'''
TOPICS = ('parts', 'light_barriers', 'light_barrier_edges', 'belt_states', 'actuator_states',
          'faults')


def _run(layout: str, scenario: str) -> dict:
    with LockstepTwin(seed=4, layout=layout, chunk=50, scenario=scenario) as twin:
        twin.step(1500)
        return {t: twin.digest(t) for t in TOPICS}, len(twin.messages('belt_states')), \
            [decode_fault_state(m) for m in twin.messages('faults')]


def test_a_scenario_gives_the_same_streams_composed_split_and_rerun(tmp_path):
    path = tmp_path / 'scenario.yaml'
    path.write_text(SCENARIO)
    composed, belt_messages, states = _run('composed', str(path))
    assert composed == _run('composed', str(path))[0]
    assert _run('split', str(path))[0] == composed
    assert belt_messages == 1500 - 50  # silenced for 50 steps
    injected = [i for s in states for i in s.injected]
    assert len(injected) == 10 and states[-1].total_injected == 10  # the triggers fired


def test_services_the_latched_stream_and_diagnostics():
    with LockstepTwin(quiet_cell(), seed=1) as twin:
        twin.step(10)
        fault = twin.inject_fault('belt_slip', 'main', factor=0.5, duration=0.1)
        twin.step(1)
        assert twin.active_faults()[fault].params == (('factor', 0.5),)
        assert twin.belt('main').speed == pytest.approx(0.25)
        coordinator = twin.composed.coordinator
        status = coordinator.diagnostics(twin.time_ns).status[1]
        assert status.name == 'conveyor_twin: faults' and status.level == status.WARN
        assert 'belt_slip main [factor=0.5] (id 1)' in status.message
        twin.step(100)  # expired
        assert twin.active_faults() == {}
        values = {kv.key: kv.value for kv in coordinator.diagnostics(twin.time_ns).status[1]
                  .values}
        assert values['faults_injected'] == '1' and values['faults_expired'] == '1'
        with pytest.raises(Exception, match="parameter 'factor' = 2.0 is outside"):
            twin.inject_fault('belt_slip', 'main', factor=2.0)
        with pytest.raises(Exception, match='param'):
            twin.inject_fault('barrier_chatter', 'lb_exit', frequency=float('nan'))
        twin.step(1)
        assert twin.active_faults() == {}  # nothing changed
        values = {kv.key: kv.value for kv in coordinator.diagnostics(twin.time_ns).status[1]
                  .values}
        assert values['faults_rejected'] == '2' and 'not finite' in values[
            'faults_last_rejection']


def _cli(*args: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'conveyor_twin.cli', *args],
                          capture_output=True, text=True, timeout=300, **kwargs)


def test_run_refuses_an_invalid_scenario_and_records_a_valid_one(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('faults:\n  - {kind: belt_stall, target: side, at: {step: 5}}\n')
    out = _cli('run', '--mode', 'fast', '--duration', '0.1', '--scenario', str(bad))
    assert out.returncode == 2
    assert f'{bad}: faults[0]' in out.stderr and "belt 'side' is unknown" in out.stderr
    assert 'the twin was not started' in out.stderr
    good = tmp_path / 'good.yaml'
    good.write_text(SCENARIO)
    recording = tmp_path / 'run.mcap'
    out = _cli('run', '--mode', 'fast', '--duration', '1.2', '--quiet', '--markers-rate', '0',
               '--seed', '4', '--scenario', str(good), '--record', str(recording))
    assert out.returncode == 0, out.stderr
    assert 'fault injected at step 300: belt_slip main [factor=0.6]' in out.stderr
    report = resimulate(str(recording))
    assert report.ok, report.difference
    assert report.faults == 10 and report.compared['/faults'] > 0
