"""The split layout on the cells with a curved belt (an ``auto`` zone along an L-shaped line)
and a transfer unit: the roles, talking bytes only, give the composed twin's frames."""

from pathlib import Path

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import MacroOutput, MicroOutput

from .test_roles import Frames, split_in_memory

EXAMPLES = Path(__file__).resolve().parents[2] / 'conveyor_twin' / 'cell' / 'examples'
STEPS = 1500


@pytest.mark.parametrize('name, command', [
    ('l_line', ('belt', 'outfeed', 0.1)),       # the outfeed slows: the curve fills up
    ('transfer', ('actuator', 'xfer', 0.02)),   # the transfer unit lifts: parts turn aside
])
def test_split_in_memory_equals_composed_on_curves_and_transfers(name, command):
    cell = load_cell(EXAMPLES / f'{name}.yaml')
    kind, target, value = command
    assert target in [b.name for b in cell.belts] + [a.name for a in cell.actuators]
    composed = build_twin(cell, seed=3, check_balance=True)
    c_frames, s_frames = Frames(), Frames()
    c_out = TwinOutput([MicroOutput(composed.micro), MacroOutput(composed.macro)])
    c_out.subscribe(c_frames)
    composed.twin.step_listeners.append(c_out.on_step)
    coordinator, micro, macro = split_in_memory(cell, 3)
    micro.output.subscribe(s_frames)
    macro.output.subscribe(s_frames)
    for twin in (composed.twin, coordinator.twin):
        twin.step(STEPS // 3)
        if kind == 'belt':
            twin.commands.submit_belt(target, value)
        else:
            twin.commands.submit_actuator(target, value)
        twin.step(STEPS - STEPS // 3)
    assert micro.stage.sim.state_bytes() == composed.micro.sim.state_bytes()
    assert micro.stage.sim.n > 0, 'parts should be on the line'
    for a, b in zip(macro.stage.grids, composed.macro.grids):
        assert a.density.tobytes() == b.density.tobytes()
    merged = [{**a, **b} for a, b in zip(s_frames.seen[0::2], s_frames.seen[1::2])]
    assert len(merged) == len(c_frames.seen) == STEPS
    assert merged == c_frames.seen
