"""The plant file: the example and the test plants load; every error names file, key path,
value and what is allowed."""

from pathlib import Path

import pytest
import yaml

from conveyor_twin.cell.errors import CellError
from conveyor_twin.plant.errors import PlantError
from conveyor_twin.plant.loader import load_plant, plant_from_mapping
from conveyor_twin.plant.model import ID_RANGE

ROOT = Path(__file__).resolve().parents[2]
RES = ROOT / 'test' / 'resources' / 'plant'
EXAMPLE = ROOT / 'examples' / 'plant' / 'plant.yaml'


def chain() -> dict:
    return yaml.safe_load((RES / 'chain.yaml').read_text())


def error(data: dict) -> PlantError:
    with pytest.raises(PlantError) as info:
        plant_from_mapping(data, 'p.yaml', RES)
    return info.value


def test_example_plant_loads():
    plant = load_plant(EXAMPLE)
    assert [c.name for c in plant.cells] == ['infeed', 'deflector', 'sorter', 'buffer_left',
                                             'buffer_right']
    assert [k.delay_steps for k in plant.links] == [200, 200, 100, 100]
    assert plant.cell('sorter').seed == 1 + 2
    # sinks feeding links are the links' now; the others stay sinks of the plant
    assert [s.name for s in plant.cell('deflector').cell.sinks] == ['reject_bin']
    assert plant.cell('sorter').cell.sinks == ()
    assert len(plant.links_to('deflector')) == 1 and len(plant.links_from('sorter')) == 2
    assert plant.min_delay == 100 and len(plant.cells) * ID_RANGE <= 2 ** 32


def test_chain_delays_in_steps_and_seconds():
    plant = load_plant(RES / 'chain.yaml')
    assert [k.delay_steps for k in plant.links] == [40, 30]
    assert [k.capacity for k in plant.links] == [4, 0]
    assert plant.links[0].type_map == (0,)
    # the entry frame sits at the belt start, along the belt
    entry = plant.links[0].entry
    assert (entry.x, entry.y, entry.yaw, entry.half_width) == (0.0, 0.0, 0.0, 0.1)


@pytest.mark.parametrize('edit, key_path, expected', [
    (lambda d: d['links'][0]['to'].update(cell='nowhere'), 'links[0].to.cell',
     "one of the plant's cells"),
    (lambda d: d['links'][0].update(delay_steps=0), 'links[0].delay_steps',
     'an integer in [1,'),
    (lambda d: d['links'][1].update(delay=0.0005), 'links[1].delay', 'a finite number in'),
    (lambda d: d['links'][1].update(delay=0.0305), 'links[1].delay',
     'a whole number of steps'),
    (lambda d: d['links'][1].update(delay_steps=5), 'links[1].delay',
     'exactly one of delay [s] or delay_steps'),
    (lambda d: d['links'][0]['from'].update(sink='nope'), 'links[0].from.sink',
     "a sink of cell 'feeder'"),
    (lambda d: d['links'][0]['from'].update(belt='main'), 'links[0].from.sink',
     'exactly one of'),
    (lambda d: d['links'][0]['to'].update(belt='side'), 'links[0].to.belt',
     "a belt of cell 'first'"),
    (lambda d: d['cells'][2].update(name='first'), 'cells[2].name',
     'a cell name not used before'),
    (lambda d: d['cells'][2].update(namespace='feeder'), 'cells[2].namespace',
     'a namespace not used'),
    (lambda d: d['cells'][1].update(name='has space'), 'cells[1].name', 'a ROS name token'),
    (lambda d: d['cells'][1].update(file='missing.yaml'), 'cells[1].file',
     'an existing cell file'),
    (lambda d: d['cells'][1].update(colour='red'), 'cells[1].colour', 'no such key here'),
    (lambda d: d['links'][1].update(name='feed_first'), 'links[1].name',
     'a link name not used before'),
    (lambda d: d['links'][1]['from'].update(cell='feeder'), 'links[1].from',
     "an exit no other link uses (link 'feed_first' does)"),
    (lambda d: d['links'][0].update(capacity=-1), 'links[0].capacity', 'an integer in [0,'),
    (lambda d: d['cells'][0]['placement'].update(yaw='north'), 'cells[0].placement.yaw',
     'a finite number'),
])
def test_errors_name_file_key_value_and_expectation(edit, key_path, expected):
    data = chain()
    data['cells'][0]['placement'] = {}
    edit(data)
    exc = error(data)
    assert exc.file == 'p.yaml' and exc.key_path == key_path, str(exc)
    assert expected in exc.expected, str(exc)
    assert str(exc).startswith(f'p.yaml: {key_path}: got ')


def test_a_link_into_another_part_type_set_is_refused(tmp_path):
    text = (RES / 'relay.yaml').read_text().replace('name: disc', 'name: puck')
    (tmp_path / 'relay.yaml').write_text(text)
    (tmp_path / 'feeder.yaml').write_text((RES / 'feeder.yaml').read_text())
    exc = error_at(tmp_path, chain())
    assert exc.key_path == 'links[0].to' and "part type 'disc'" in exc.expected


def error_at(base: Path, data: dict) -> PlantError:
    with pytest.raises(PlantError) as info:
        plant_from_mapping(data, 'p.yaml', base)
    return info.value


def test_an_exit_in_a_macro_zone_is_refused():
    cells = ROOT / 'conveyor_twin' / 'cell' / 'examples'
    data = {'plant': {'name': 'p'},
            'cells': [{'name': 'a', 'file': str(cells / 'multiscale.yaml')},
                      {'name': 'b', 'file': str(cells / 'multiscale.yaml')}],
            'links': [{'name': 'ab', 'from': {'cell': 'a', 'belt': 'main'},
                       'to': {'cell': 'b', 'region': [1.0, -0.2, 1.2, 0.2]},
                       'delay_steps': 10}]}
    exc = error(data)
    assert exc.key_path == 'links[0].to' and "zone 'bulk'" in exc.expected


def test_cells_must_share_the_step(tmp_path):
    (tmp_path / 'feeder.yaml').write_text((RES / 'feeder.yaml').read_text())
    (tmp_path / 'relay.yaml').write_text((RES / 'relay.yaml').read_text()
                                         .replace('step: 0.001', 'step: 0.002'))
    exc = error_at(tmp_path, chain())
    assert exc.key_path == 'cells[1].file' and "the plant's step 0.001 s" in exc.expected


def test_an_invalid_cell_file_names_the_cell_file(tmp_path):
    (tmp_path / 'feeder.yaml').write_text((RES / 'feeder.yaml').read_text()
                                          .replace('speed: 1.0', 'speed: fast'))
    (tmp_path / 'relay.yaml').write_text((RES / 'relay.yaml').read_text())
    with pytest.raises(CellError) as info:
        plant_from_mapping(chain(), 'p.yaml', tmp_path)
    assert info.value.file.endswith('feeder.yaml') and 'belts[0].speed' in str(info.value)


def test_unreadable_and_non_yaml_files(tmp_path):
    with pytest.raises(PlantError, match='<file>'):
        load_plant(tmp_path / 'none.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('plant: [\n')
    with pytest.raises(PlantError, match='valid YAML'):
        load_plant(bad)
    top = tmp_path / 'top.yaml'
    top.write_text('- 1\n')
    with pytest.raises(PlantError, match='a mapping of keys to values'):
        load_plant(top)


def test_the_default_cell_by_name():
    data = {'plant': {'name': 'p'}, 'cells': [{'name': 'a', 'file': 'default'}]}
    plant = plant_from_mapping(data, 'p.yaml', RES)
    assert plant.cells[0].cell.settings.name == 'seed_test_rig' and plant.links == ()


def test_a_ring_of_cells_is_refused_naming_the_cycle():
    data = chain()
    data['links'].append({'name': 'back', 'from': {'cell': 'second', 'sink': 'exit'},
                          'to': {'cell': 'first', 'belt': 'main'}, 'delay_steps': 10})
    e = error(data)
    assert e.key_path == 'links[2]' and e.value == 'back'
    assert 'first -> second -> first (links first_second, back)' in str(e)
    assert str(e).startswith('p.yaml: links[2]: got ')


def test_a_cell_feeding_itself_is_refused():
    data = chain()
    data['links'].append({'name': 'loop', 'from': {'cell': 'second', 'sink': 'exit'},
                          'to': {'cell': 'second', 'belt': 'main'}, 'delay_steps': 10})
    e = error(data)
    assert e.key_path == 'links[2]' and 'cycle second -> second (links loop)' in str(e)
