"""Scenario files: validation with named errors, timed and triggered faults, re-arming."""

from pathlib import Path

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.faults.scenario import load_scenario, scenario_from_text, ScenarioError
from test.faults.test_faults import twin

EXAMPLE = Path(__file__).resolve().parents[2] / 'examples' / 'scenarios' / 'stuck_exit.yaml'


@pytest.mark.parametrize('text, where, expected', [
    ('faults: []', 'faults', 'a non-empty list of faults'),
    ('faults: [{kind: belt_melt, target: main, at: {step: 1}}]', 'faults[0].kind', 'one of'),
    ('faults: [{kind: belt_stall, target: side, at: {step: 1}}]', 'faults[0]',
     "belt 'side' is unknown"),
    ('faults: [{kind: belt_stall, target: main, at: {step: 0}}]', 'faults[0].at.step',
     'an integer >= 1'),
    ('faults: [{kind: belt_stall, target: main, at: {hour: 1}}]', 'faults[0].at', 'one of'),
    ('faults: [{kind: belt_slip, target: main, params: {factor: .nan}, at: {time: 1}}]',
     'faults[0]', 'not finite'),
    ('faults: [{kind: belt_stall, target: main, at: {time: 1}, duration: -2}]',
     'faults[0].duration', '>= 0'),
    ('faults: [{kind: belt_stall, target: main, at: {after_edges: {barrier: lb_x, count: 2}}}]',
     'faults[0].at.after_edges.barrier', 'a light barrier of the cell'),
    ('faults: [{kind: belt_stall, target: main, at: {step: 1}, colour: red}]',
     'faults[0].colour', 'one of kind'),
    ('faults: [{kind: belt_stall, target: main, at: {step: 1}', 'line', 'valid YAML'),
])
def test_invalid_scenarios_are_refused_with_the_place_and_the_reason(text, where, expected):
    with pytest.raises(ScenarioError) as err:
        scenario_from_text(text, load_cell(), 'bad.yaml')
    message = str(err.value)
    assert message.startswith(f'bad.yaml: {where}') and expected in message, message


def test_the_example_scenario_is_valid_and_has_triggers():
    scenario = load_scenario(str(EXAMPLE), load_cell())
    assert len(scenario.entries) == 4 and scenario.conditional
    with pytest.raises(ScenarioError, match='a readable UTF-8 YAML file'):
        load_scenario('/no/such/scenario.yaml', load_cell())


def test_timed_and_triggered_faults_fire_once_and_again_after_a_reset():
    a, rec = twin()
    scenario = scenario_from_text(
        'faults:\n'
        '  - {kind: belt_stall, target: main, at: {time: 0.2}, duration: 0.1}\n'
        '  - {kind: barrier_stuck_free, target: lb_exit, at: {after_edges: {barrier: lb_infeed,'
        ' count: 2}}}\n', a.cell)
    a.arm_scenario(scenario)
    a.step(6000)
    stalled = [s['step'] for s in rec.steps if s['belt_speed'][0] == 0.0]
    assert stalled[0] == 200 and stalled[-1] >= 299
    assert a.micro.barrier_edge_count()[0] >= 2
    active = {f.kind for f in a.twin.faults.active.values()}
    assert active == {'barrier_stuck_free'}
    a.twin.reset()
    assert a.twin.faults.active == {}
    a.step(250)
    assert a.twin.faults.counters()['injected'] == 3  # the stall again, after the reset
    assert [f.kind for f in a.twin.faults.active.values()] == ['belt_stall']
