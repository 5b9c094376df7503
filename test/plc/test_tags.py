"""The PLC tag map of every shipped cell: unique paths, contiguous Modbus tables, stable."""

import csv
import io
import math
from pathlib import Path

import pytest
import yaml

from conveyor_twin.cell import load_cell, load_cell_text
from conveyor_twin.plc.tags import (browse_names, MODBUS_TABLES, modbus_value, modbus_words,
                                    tag_map, TagKind)

ROOT = Path(__file__).resolve().parents[2]
PACKAGE_CELLS = ROOT / 'conveyor_twin' / 'cell'


def shipped_cells():
    """Every cell file the repository ships (plant files excluded)."""
    files = sorted(PACKAGE_CELLS.glob('*.yaml'))
    files += sorted((PACKAGE_CELLS / 'examples').glob('*.yaml'))
    for path in sorted((ROOT / 'examples' / 'plant').glob('*.yaml')):
        if 'plant' not in (yaml.safe_load(path.read_text()) or {}):
            files.append(path)
    return files


CELLS = shipped_cells()


def test_every_shipped_cell_is_found() -> None:
    names = {p.name for p in CELLS}
    assert {'default_cell.yaml', 'multiscale.yaml', 'sorting.yaml', 'merge.yaml',
            'infeed.yaml', 'sorter.yaml', 'buffer.yaml'} <= names


@pytest.mark.parametrize('path', CELLS, ids=lambda p: p.name)
def test_map_of_a_shipped_cell_has_unique_paths_and_contiguous_tables(path: Path) -> None:
    cell = load_cell(path)
    tags = tag_map(cell)
    paths = [t.path for t in tags.tags]
    assert len(set(paths)) == len(paths)
    assert all(tags.by_path(p).path == p for p in paths)
    expected = (9 + 4 + 5 * len(cell.light_barriers) + 2 * len(cell.belts)
                + 4 * len(cell.actuators))  # Target, Position, Stalled, Load
    assert len(tags.tags) == expected
    for table in MODBUS_TABLES:
        address = 0
        for tag in tags.modbus(table):  # no overlap, no gap
            assert tag.modbus_address == address, (table, tag.path)
            assert tag.modbus_words == (2 if tag.modbus_type in ('uint32', 'float32') else 1)
            if tag.modbus_words == 2:
                assert tag.modbus_address % 2 == 0, tag.path
            address += tag.modbus_words
        assert tags.modbus_size(table) == address
    assert tags.modbus('coil') == ()
    # the twin's and the lockstep's addresses are the same for every cell
    assert tags.by_path('Lockstep/Done').modbus_address == 0
    assert tags.by_path('Mode').modbus_address == 14
    assert tags.by_path('Lockstep/DoneTick').modbus_address == 15
    assert tags.by_path('Lockstep/Tick').modbus_address == 0
    assert tags.by_path('Lockstep/TickSteps').modbus_address == 1
    # the table of each kind of tag
    for tag in tags.tags:
        if tag.writable:
            assert tag.modbus_table == 'holding'
        if tag.modbus_type == 'bit':
            assert tag.kind is TagKind.BOOL and tag.modbus_table == 'discrete'


@pytest.mark.parametrize('path', CELLS, ids=lambda p: p.name)
def test_map_is_stable(path: Path) -> None:
    assert tag_map(load_cell(path)).tags == tag_map(load_cell(path)).tags


def test_order_is_twin_lockstep_barriers_belts_actuators() -> None:
    cell = load_cell()
    tags = tag_map(cell)
    groups = [t.source[0].replace('ledger', 'twin') for t in tags.tags]
    runs = [g for i, g in enumerate(groups) if i == 0 or groups[i - 1] != g]
    assert runs == ['twin', 'lockstep', 'barrier', 'belt', 'actuator']
    barrier_names = [t.target for t in tags.tags if t.source[0] == 'barrier'][::5]
    assert barrier_names == [b.name for b in cell.light_barriers]
    assert [t.path for t in tags.tags if t.target == 'lb_infeed'] == [
        'Barriers/lb_infeed/Blocked', 'Barriers/lb_infeed/RisingEdges',
        'Barriers/lb_infeed/FallingEdges', 'Barriers/lb_infeed/LastRisingTime',
        'Barriers/lb_infeed/LastFallingTime']


def test_writable_tags_are_setpoints_targets_and_the_tick() -> None:
    tags = tag_map(load_cell())
    assert sorted(t.path for t in tags.tags if t.writable) == [
        'Actuators/pusher/Target', 'Actuators/stopper/Target', 'Belts/main/SpeedSetpoint',
        'Lockstep/Tick', 'Lockstep/TickSteps']
    assert tags.by_path('Actuators/pusher/Target').unit == 'm'
    assert tags.by_path('Belts/main/SpeedSetpoint').unit == 'm/s'
    sorting = tag_map(load_cell(PACKAGE_CELLS / 'examples' / 'sorting.yaml'))
    rotary = [t for t in sorting.tags if t.path.endswith('/Target') and t.unit == 'rad']
    assert rotary, 'the diverter of the sorting cell is rotary'


def test_names_invalid_in_a_browse_name_are_replaced_and_kept_unique() -> None:
    assert browse_names(['a/b', 'a b', 'a_b', 'ok-1', '']) == ['a_b', 'a_b_2', 'a_b_3', 'ok-1',
                                                             '_']
    text = (PACKAGE_CELLS / 'default_cell.yaml').read_text()
    text = text.replace('lb_infeed', 'lb/in.feed').replace('lb_exit', 'lb in:feed')
    cell = load_cell_text(text)
    tags = tag_map(cell)
    blocked = [t for t in tags.tags if t.path.endswith('/Blocked')]
    assert [t.path for t in blocked] == ['Barriers/lb_in_feed/Blocked',
                                         'Barriers/lb_after_deflector/Blocked',
                                         'Barriers/lb_in_feed_2/Blocked']
    assert [t.target for t in blocked] == ['lb/in.feed', 'lb_after_deflector', 'lb in:feed']


def test_unknown_path_and_table_name_themselves() -> None:
    tags = tag_map(load_cell())
    with pytest.raises(KeyError, match='Belts/nope'):
        tags.by_path('Belts/nope')
    with pytest.raises(ValueError, match="'register'.*coil, discrete, input, holding"):
        tags.modbus('register')


def test_csv_and_markdown_have_one_row_per_tag() -> None:
    tags = tag_map(load_cell())
    rows = list(csv.reader(io.StringIO(tags.to_csv())))
    assert rows[0] == ['path', 'opcua_type', 'unit', 'access', 'modbus_table',
                       'modbus_address', 'modbus_words', 'modbus_type', 'description']
    assert len(rows) == len(tags.tags) + 1
    by_path = {r[0]: r for r in rows[1:]}
    assert by_path['Belts/main/SpeedSetpoint'] == [
        'Belts/main/SpeedSetpoint', 'Double', 'm/s', 'read/write', 'holding', '2', '2',
        'float32', "target speed of belt 'main', |v| <= 2"]
    assert by_path['ActiveFaults'][4:8] == ['', '', '', '']
    assert by_path['(Lockstep/Tick)'][4] == 'holding'
    lines = tags.to_markdown().splitlines()
    assert len(lines) == len(tags.tags) + 2
    assert lines[0].startswith('| path | opcua_type |')
    assert all(line.count(' | ') == 8 for line in lines[2:])  # '|' in a text is escaped
    assert '| Lockstep/Tick (Modbus only) |' in tags.to_markdown()


def test_modbus_encoding_is_big_endian_words() -> None:
    tags = tag_map(load_cell())
    time_tag = tags.by_path('SimulationTime')
    assert modbus_words(time_tag, 70.0001) == (70000 >> 16, 70000 & 0xFFFF)
    assert modbus_value(time_tag, modbus_words(time_tag, 70.0)) == 70000
    step = tags.by_path('Step')
    assert modbus_words(step, 2 ** 32 + 5) == (0, 5)
    speed = tags.by_path('Belts/main/SpeedSetpoint')
    assert modbus_words(speed, 1.0) == (0x3F80, 0x0000)
    assert modbus_value(speed, (0x3F80, 0)) == 1.0
    assert math.isnan(modbus_value(speed, (0x7FC0, 0)))
    assert modbus_words(tags.by_path('Mode'), 'lockstep') == (2,)
    assert modbus_words(tags.by_path('Lockstep/Done'), True) == (1,)
    assert modbus_words(tags.by_path('Barriers/lb_exit/LastRisingTime'), 0.0025) == (0, 3)
    assert modbus_words(speed, -1e300) == (0xFF80, 0)  # -inf
    stopper = tags.by_path('Actuators/stopper/Target')  # range [0, 0.008] m
    assert modbus_value(stopper, modbus_words(stopper, 0.008)) == 0.008
    assert modbus_value(speed, modbus_words(speed, 0.1)) == 0.1
    with pytest.raises(ValueError, match='takes 2 registers, got 1'):
        modbus_value(speed, (1,))
