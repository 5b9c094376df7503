"""``actuator_offset``: the actuator moves to its offset (and back once cleared) at its own speed,
and what ``actuator_states`` reports is where the simulated actuator is, at every step, for every
actuator kind."""

import math
from pathlib import Path

import pytest

import conveyor_twin.cell
from conveyor_twin.cell import load_cell
from conveyor_twin.faults.model import FaultSpec
from test.faults.test_faults import twin

CASES = [(None, 'pusher'), (None, 'stopper'), ('sorting.yaml', 'diverter'),
         ('transfer.yaml', 'xfer')]


EXAMPLES = Path(conveyor_twin.cell.__file__).parent / 'examples'


def _cell(name):
    return load_cell() if name is None else load_cell(EXAMPLES / name)


def _follow(a, rec, index: int, steps: int) -> list:
    """Step ``steps`` times; return the reported positions, each checked against the micro
    simulation's actuator at the end of the same step."""
    reported = []
    for _ in range(steps):
        a.step(1)
        shown = float(rec.steps[-1]['actuator'][index])
        assert shown == float(a.micro.sim.actuator_position[index]), f'step {a.twin.step_index}'
        reported.append(shown)
    return reported


@pytest.mark.parametrize('cell_file, name', CASES)
def test_offset_moves_at_the_actuators_speed_and_is_reported_where_it_is(cell_file, name):
    a, rec = twin(cell=_cell(cell_file))
    index = [x.name for x in a.cell.actuators].index(name)
    act = a.cell.actuators[index]
    low, high = act.position_range
    dx = act.max_speed * a.cell.settings.step         # its move per step [m or rad]
    offset = 0.6 * (high - low)
    start = act.initial_position
    fault = a.twin.faults.inject(FaultSpec('actuator_offset', name, {'offset': offset}))
    ramp_steps = math.ceil(offset / dx)
    shown = _follow(a, rec, index, ramp_steps + 5)
    assert shown[0] == pytest.approx(start + dx, rel=1e-9)   # one step's move, not the offset
    assert shown[ramp_steps - 2] < start + offset
    assert shown[-1] == pytest.approx(start + offset, rel=1e-9)
    # driven to the far end, it stops at its range's end
    a.twin.commands.submit_actuator(name, high)
    shown = _follow(a, rec, index, math.ceil((high - low) / dx) + 5)
    assert shown[-1] == high
    # driven back, it sits its offset above its range's start
    a.twin.commands.submit_actuator(name, low)
    shown = _follow(a, rec, index, math.ceil((high - low) / dx) + 5)
    assert shown[-1] == pytest.approx(low + offset, rel=1e-9)
    # cleared, it moves back to where it is driven at its speed
    a.twin.faults.clear(fault.id)
    shown = _follow(a, rec, index, ramp_steps + 5)
    assert shown[0] == pytest.approx(low + offset - dx, rel=1e-9)
    assert shown[-1] == low and not a.twin.fault_actuation.busy


def test_slow_and_offset_together_move_at_the_slowed_speed():
    a, rec = twin()
    act = a.cell.actuators[0]
    dx = act.max_speed * a.cell.settings.step
    a.twin.faults.inject(FaultSpec('actuator_slow', act.name, {'factor': 0.5}))
    a.twin.faults.inject(FaultSpec('actuator_offset', act.name, {'offset': 0.1}))
    shown = _follow(a, rec, 0, 10)
    assert shown[0] == pytest.approx(act.initial_position + 0.5 * dx, rel=1e-9)
