"""PlcWriter: a PLC's writes become validated commands; anything else is refused and counted."""

import math

import numpy as np
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.commands import CommandKind
from conveyor_twin.plc.tags import tag_map
from conveyor_twin.plc.writes import PlcWriter, WriteRejected
from test.plc.test_tags import PACKAGE_CELLS


@pytest.fixture
def twin_and_tags():
    cell = load_cell()
    built = build_twin(cell, seed=1)
    return built, tag_map(cell)


def test_a_belt_write_is_applied_at_the_next_step_with_its_origin(twin_and_tags) -> None:
    built, tags = twin_and_tags
    seen = []
    built.twin.step_listeners.append(lambda inp, commands: seen.append(list(commands)))
    writer = PlcWriter(built.twin.commands, sender='modbus')
    built.step(1)
    command = writer.write(tags.by_path('Belts/main/SpeedSetpoint'), 1.25,
                           client='127.0.0.1:50200')
    assert (command.kind, command.name, command.value) == (CommandKind.BELT, 'main', 1.25)
    assert built.twin.actuation.belt_target[0] == 0.5  # queued, not applied yet
    built.step(1)
    assert seen[-1] == [command.__class__(CommandKind.BELT, 'main', 0, 1.25, 2,
                                          'modbus 127.0.0.1:50200', 1)]
    assert built.twin.actuation.belt_target[0] == 1.25
    built.step(1000)
    assert built.twin.actuation.belt_speed[0] == pytest.approx(1.25)
    assert (writer.accepted, writer.rejected) == (1, 0)


def test_an_actuator_write_moves_the_actuator_and_sequences_count(twin_and_tags) -> None:
    built, tags = twin_and_tags
    writer = PlcWriter(built.twin.commands, sender='opcua')
    # a float32 range limit means the limit (the float32 nearest 0.008 is above it)
    first = writer.write(tags.by_path('Actuators/stopper/Target'), np.float32(0.008))
    assert first.value == 0.008
    second = writer.write(tags.by_path('Actuators/pusher/Target'), 0)
    assert (first.sender, first.sequence, second.sequence) == ('opcua', 1, 2)
    assert (second.kind, second.name, second.value) == (CommandKind.ACTUATOR, 'pusher', 0.0)
    built.step(200)
    assert built.twin.actuation.actuator_target[1] == 0.008
    assert built.twin.actuation.actuator_position[1] == pytest.approx(0.008, rel=1e-6)


REFUSALS = [
    ('Belts/main/SpeedSetpoint', 2.5, 'out_of_range', r"outside \[-2, 2\] m/s"),
    ('Belts/main/SpeedSetpoint', math.nan, 'not_finite', 'not finite'),
    ('Belts/main/SpeedSetpoint', math.inf, 'not_finite', 'not finite'),
    ('Belts/main/SpeedSetpoint', -math.inf, 'not_finite', 'not finite'),
    ('Belts/main/SpeedSetpoint', 10 ** 400, 'out_of_range', 'outside the range of a float'),
    ('Belts/main/SpeedSetpoint', '1.0', 'bad_type', "'1.0' of type str is not a number"),
    ('Belts/main/SpeedSetpoint', True, 'bad_type', 'True of type bool is not a number'),
    ('Belts/main/SpeedSetpoint', np.bool_(True), 'bad_type', 'is not a number'),
    ('Belts/main/SpeedSetpoint', None, 'bad_type', 'None of type NoneType'),
    ('Actuators/stopper/Target', 0.01, 'out_of_range', r"outside \[0, 0.008\] m"),
    ('Actuators/pusher/Target', -0.1, 'out_of_range', r"outside \[0, 0.5\] m"),
    ('Belts/main/ActualSpeed', 1.0, 'not_writable', 'not writable'),
    ('Barriers/lb_exit/Blocked', True, 'not_writable', 'not writable'),
    ('Lockstep/Tick', 1, 'not_writable', 'not writable'),
    ('SimulationTime', 1.0, 'not_writable', 'not writable'),
]


@pytest.mark.parametrize('path, value, reason, message', REFUSALS,
                         ids=[f'{r[0]}={r[1]!r}' for r in REFUSALS])
def test_a_bad_write_is_refused_counted_and_not_applied(twin_and_tags, path, value, reason,
                                                        message) -> None:
    built, tags = twin_and_tags
    book = built.twin.commands
    writer = PlcWriter(book, sender='opcua')
    with pytest.raises(WriteRejected, match=message) as info:
        writer.write(tags.by_path(path), value)
    assert info.value.reason == reason
    assert path in info.value.message
    assert book.rejected[reason] == 1 and book.rejected_total == 1
    assert writer.rejected == 1 and writer.accepted == 0
    assert book.drain(1) == []
    built.step(10)
    assert built.twin.actuation.belt_target[0] == 0.5
    assert list(built.twin.actuation.actuator_target) == [0.0, 0.0]


def test_read_only_refuses_every_write(twin_and_tags) -> None:
    built, tags = twin_and_tags
    book = built.twin.commands
    writer = PlcWriter(book, sender='modbus', read_only=True)
    for path in ('Belts/main/SpeedSetpoint', 'Actuators/pusher/Target'):
        with pytest.raises(WriteRejected, match='read-only') as info:
            writer.write(tags.by_path(path), 0.1)
        assert info.value.reason == 'read_only'
    assert book.rejected['read_only'] == 2
    assert book.drain(1) == []


def test_a_tag_of_another_cell_is_refused_by_name(twin_and_tags) -> None:
    built, _ = twin_and_tags
    other = tag_map(load_cell(PACKAGE_CELLS / 'examples' / 'merge.yaml'))
    belt = next(t for t in other.tags if t.writable and t.target not in ('main',)
                and t.source[0] == 'belt')
    writer = PlcWriter(built.twin.commands, sender='opcua')
    with pytest.raises(WriteRejected, match='unknown belt') as info:
        writer.write(belt, 0.1)
    assert info.value.reason == 'unknown_belt'
