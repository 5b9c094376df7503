"""docs/cell_format.md states the loader's defaults and the default cell's values."""

import math
import re
from pathlib import Path

import pytest

from conveyor_twin.cell import cell_from_mapping, load_cell

DOC = Path(__file__).resolve().parents[2] / 'docs' / 'cell_format.md'

#: A cell giving only the required keys, so every other key takes its default.
MINIMAL = {
    'cell': {'name': 'minimal'},
    'belts': [{'name': 'main', 'start': [0.0, 0.0], 'end': [2.0, 0.0], 'width': 0.4},
              {'name': 'bend', 'curve': {'centre': [2.0, 1.0], 'inner_radius': 0.8,
                                         'outer_radius': 1.2, 'start_angle': -90,
                                         'end_angle': 0, 'direction': 'ccw'}}],
    'obstacles': [{'name': 'wall', 'kind': 'wall', 'points': [[0.0, 0.2], [2.0, 0.2]]},
                  {'name': 'fin', 'kind': 'deflector', 'points': [[1.0, 0.2], [1.2, 0.0]]}],
    'part_types': [{'name': 'disc', 'shape': 'disc', 'radius': 0.005, 'height': 0.01,
                    'mass': 0.005}],
    'sources': [{'name': 'feed', 'part_type': 'disc', 'region': [0.0, -0.1, 0.2, 0.1],
                 'rate': 5.0}],
    'actuators': [{'name': 'arm', 'kind': 'diverter', 'base': [1.5, -0.2], 'axis': [1.0, 0.0],
                   'length': 0.3, 'width': 0.01, 'max_position': 0.8, 'max_speed': 1.0},
                  {'name': 'lift', 'kind': 'transfer', 'base': [1.0, 0.0], 'axis': [0.0, 1.0],
                   'length': 0.4, 'width': 0.2, 'stroke': 0.02, 'max_speed': 0.1,
                   'surface_speed': 0.5}],
    'zones': [{'name': 'z', 'region': [0.0, -0.2, 2.0, 0.2]}],
}

#: Section of the document -> the loaded object holding its keys.
SECTIONS = {
    'cell': lambda c: c.settings,
    'belts': lambda c: c.belts[0],
    'obstacles': lambda c: c.obstacles[0],
    'part_types': lambda c: c.part_types[0],
    'sources': lambda c: c.sources[0],
    'actuators': lambda c: c.actuators[0],
    'zones': lambda c: c.zones[0],
    'micro': lambda c: c.micro,
    'macro': lambda c: c.macro,
}
#: (section, key prefix) -> the loaded object holding the keys of that row (a curved belt).
SUBSECTIONS = {('belts', 'curve.'): lambda c: c.belts[1]}
#: Values the loader stores differently from how the document writes them.
STORED = {('sources', 'velocity'): {'belt': None}, ('sources', 'yaw'): {'random': None},
          ('belts', 'curve.guide_rails'): {'false': False}}


def _defaults():
    """Yield (section, key, default text) of every table row whose default is one literal."""
    section = None
    for line in DOC.read_text('utf-8').splitlines():
        heading = re.match(r'## `(\w+)`', line)
        if heading:
            section = heading.group(1)
            continue
        row = re.match(r'\| `([\w.]+)` \| `([\w.+-]+)` \|', line)  # no formulas
        if row and section in SECTIONS:
            yield section, row.group(1), row.group(2)


def _value(obj, key: str):
    for part in key.split('.'):
        obj = getattr(obj, part)
    return getattr(obj, 'value', obj)


def test_every_literal_default_in_the_tables_is_the_loaders():
    cell = cell_from_mapping(MINIMAL, 'minimal.yaml')
    rows = list(_defaults())
    assert len(rows) > 40  # the parse found the tables
    for section, key, text in rows:
        owner = next((get for (sec, prefix), get in SUBSECTIONS.items()
                      if sec == section and key.startswith(prefix)), SECTIONS[section])
        actual = _value(owner(cell), key)
        stored = STORED.get((section, key), {})
        if text in stored:
            expected = stored[text]
        else:
            try:
                expected = float(text)
            except ValueError:
                expected = text
        if isinstance(expected, float):
            assert actual == pytest.approx(expected), (section, key, text, actual)
        else:
            assert actual == expected, (section, key, text, actual)


def test_the_polyline_thickness_defaults():
    cell = cell_from_mapping(MINIMAL, 'minimal.yaml')
    assert '| `thickness` | `0.005` wall, `0.01` deflector |' in DOC.read_text('utf-8')
    assert [o.thickness for o in cell.obstacles] == [0.005, 0.01]


def test_the_transfer_defaults():
    cell = cell_from_mapping(MINIMAL, 'minimal.yaml')
    text = DOC.read_text('utf-8')
    assert 'friction default `0.5`, part–roller' in text
    assert '| `engage_height` | `stroke/2` |' in text
    lift = cell.actuators[1]
    assert (lift.friction, lift.engage_height, lift.force_limit) == (0.5, 0.01, math.inf)


def test_the_default_cells_collision_operator_is_the_one_stated():
    text = DOC.read_text('utf-8')
    stated = re.search(r'the default cell sets ([\d.]+)', text)
    assert stated is not None
    assert float(stated.group(1)) == load_cell().macro.epsilon
