"""The PLC tags of a transfer unit: its target (written by a PLC) and its lift (read)."""

from pathlib import Path

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import CoordinatorOutput, MacroOutput, MicroOutput
from conveyor_twin.plc.state import PlcState
from conveyor_twin.plc.tags import tag_map, TagKind

CELL = Path(__file__).resolve().parents[2] / 'conveyor_twin' / 'cell' / 'examples' / 'transfer.yaml'


def test_the_transfer_has_a_writable_target_and_a_position():
    tags = tag_map(load_cell(CELL))
    target = tags.by_path('Actuators/xfer/Target')
    assert target.writable and target.kind == TagKind.FLOAT64 and target.unit == 'm'
    assert (target.modbus_table, target.modbus_type) == ('holding', 'float32')
    assert "transfer 'xfer'" in target.description and '[0, 0.02] m' in target.description
    position = tags.by_path('Actuators/xfer/Position')
    assert not position.writable and position.unit == 'm'
    assert (position.modbus_table, position.modbus_type) == ('input', 'float32')
    assert position.target == target.target == 'xfer'
    assert {'Actuators/xfer/Stalled', 'Actuators/xfer/Load'} <= {t.path for t in tags.tags}


def test_the_position_tag_shows_the_lift_moving_at_its_speed():
    cell = load_cell(CELL)
    built = build_twin(cell, seed=1)
    output = TwinOutput([CoordinatorOutput(built.twin, diagnostics=lambda t: None),
                         MicroOutput(built.micro), MacroOutput(built.macro)])
    built.twin.step_listeners.append(output.on_step)
    state = PlcState(cell, mode='fast')
    output.subscribe(state)
    target = state.map.by_path('Actuators/xfer/Target')
    position = state.map.by_path('Actuators/xfer/Position')
    built.twin.commands.submit_actuator('xfer', 0.02)
    built.step(100)                        # 0.1 s at 0.1 m/s: half its lift
    view = state.refresh()
    assert view.value(target) == 0.02
    assert view.value(position) == pytest.approx(0.01, abs=1e-12)
    built.step(150)
    assert state.refresh().value(position) == 0.02
