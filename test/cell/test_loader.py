"""The cell loader: the default cell, and bad files rejected with file, key path, value, expectation."""

import copy
import math
from pathlib import Path
import subprocess
import sys

import pytest
import yaml

from conveyor_twin.cell import CellError, cell_from_mapping, default_cell_text, load_cell
from conveyor_twin.cli import main as cli_main


@pytest.fixture
def default_doc() -> dict:
    return yaml.safe_load(default_cell_text())


def _write(tmp_path: Path, doc: dict) -> Path:
    path = tmp_path / 'cell.yaml'
    path.write_text(yaml.safe_dump(doc))
    return path


def _error_for(tmp_path: Path, doc: dict) -> CellError:
    path = _write(tmp_path, doc)
    with pytest.raises(CellError) as info:
        load_cell(path)
    assert str(path) in str(info.value)
    return info.value


def test_default_cell_reproduces_the_seed_rig() -> None:
    cell = load_cell()
    belt = cell.belts[0]
    assert belt.length > 5.0
    deflector = next(o for o in cell.obstacles if o.kind == 'deflector')
    (x0, y0), (x1, y1) = deflector.points[0], deflector.points[-1]
    mid = 0.5 * (belt.start[0] + belt.end[0])
    assert min(x0, x1) < mid < max(x0, x1) + 0.5  # mounted in the middle of the belt
    angle = math.degrees(math.atan2(abs(y1 - y0), abs(x1 - x0)))
    assert 20.0 < angle < 70.0  # at an angle across the belt, neither along nor square
    spacer = cell.part_types[cell.part_type_index(cell.sources[0].part_type)]
    assert spacer.shape == 'disc' and spacer.radius <= 0.01
    xs = [0.5 * (b.start[0] + b.end[0]) for b in cell.light_barriers]
    deflector_x = 0.5 * (x0 + x1)
    assert any(x < deflector_x for x in xs) and any(x > deflector_x for x in xs)
    kinds = {a.kind for a in cell.actuators}
    assert {'pusher', 'stopper'} <= kinds
    assert cell.sinks and cell.sources
    assert cell.settings.step == 1e-3


def test_cell_objects_are_frozen() -> None:
    cell = load_cell()
    with pytest.raises(Exception):
        cell.belts[0].speed = 3.0  # type: ignore[misc]


def test_unknown_key_is_named(tmp_path: Path, default_doc: dict) -> None:
    default_doc['belts'][0]['colour'] = 'blue'
    error = _error_for(tmp_path, default_doc)
    assert error.key_path == 'belts[0].colour'
    assert 'no such key' in error.expected and 'max_speed' in error.expected


def test_unknown_top_level_key(tmp_path: Path, default_doc: dict) -> None:
    default_doc['robots'] = []
    assert _error_for(tmp_path, default_doc).key_path == 'robots'


def test_wrong_type_is_named(tmp_path: Path, default_doc: dict) -> None:
    default_doc['belts'][0]['speed'] = 'fast'
    error = _error_for(tmp_path, default_doc)
    assert error.key_path == 'belts[0].speed'
    assert error.value == 'fast'
    assert 'number' in error.expected


def test_negative_length_is_rejected(tmp_path: Path, default_doc: dict) -> None:
    default_doc['belts'][0]['width'] = -0.5
    error = _error_for(tmp_path, default_doc)
    assert error.key_path == 'belts[0].width' and error.value == -0.5
    assert '(0, 10]' in error.expected


def test_missing_required_field(tmp_path: Path, default_doc: dict) -> None:
    del default_doc['part_types'][0]['mass']
    error = _error_for(tmp_path, default_doc)
    assert error.key_path == 'part_types[0].mass'
    assert 'required' in error.expected


def test_unknown_part_type_in_source(tmp_path: Path, default_doc: dict) -> None:
    default_doc['sources'][0]['part_type'] = 'bolt'
    error = _error_for(tmp_path, default_doc)
    assert error.key_path == 'sources[0].part_type' and error.value == 'bolt'
    assert 'spacer' in error.expected


@pytest.mark.parametrize('mutate, key_path', [
    (lambda d: d['belts'][0].update(speed=5.0), 'belts[0].speed'),
    (lambda d: d['belts'][0].update(end=[0.0, 0.0]), 'belts[0].end'),
    (lambda d: d['belts'][0].update(friction=float('nan')), 'belts[0].friction'),
    (lambda d: d['cell'].update(step=0.0), 'cell.step'),
    (lambda d: d['part_types'][0].update(shape='sphere'), 'part_types[0].shape'),
    (lambda d: d['part_types'][0].update(restitution=1.5), 'part_types[0].restitution'),
    (lambda d: d['part_types'][0].update(friction_sliding=0.9), 'part_types[0].friction_sliding'),
    (lambda d: d['obstacles'][0].update(points=[[0.0, 0.0]]), 'obstacles[0].points'),
    (lambda d: d['obstacles'][0].update(points=[[0.0, 0.0], [1.0]]), 'obstacles[0].points[1]'),
    (lambda d: d['sinks'][0].update(region=[1.0, 0.0, 0.0, 1.0]), 'sinks[0].region'),
    (lambda d: d['actuators'][0].update(initial_position=2.0), 'actuators[0].initial_position'),
    (lambda d: d['actuators'][0].update(axis=[0.0, 0.0]), 'actuators[0].axis'),
    (lambda d: d['light_barriers'].append(dict(d['light_barriers'][0])), 'light_barriers[3].name'),
    (lambda d: d['zones'][0].update(policy='meso'), 'zones[0].policy'),
    (lambda d: d['zones'][0].update(auto={'free_flow_slip': 1.5}), 'zones[0].auto.free_flow_slip'),
    (lambda d: d['macro'].update(cfl=1.5), 'macro.cfl'),
    (lambda d: d['micro'].update(capacity=0), 'micro.capacity'),
    (lambda d: d['micro'].update(capacity=True), 'micro.capacity'),
    (lambda d: d['micro'].update(contact_sweeps=0), 'micro.contact_sweeps'),
    (lambda d: d['micro'].update(contact_sweep_budget=-1), 'micro.contact_sweep_budget'),
    (lambda d: d['micro'].update(contact_tolerance=-1e-4), 'micro.contact_tolerance'),
    (lambda d: d['micro'].update(contact_tolerance=0.5), 'micro.contact_tolerance'),
    (lambda d: d['micro'].update(contact_sweeps=20, contact_sweeps_max=10),
     'micro.contact_sweeps_max'),
    (lambda d: d.update(belts=[]), 'belts'),
])
def test_out_of_range_and_malformed_values(tmp_path: Path, default_doc: dict, mutate,
                                           key_path: str) -> None:
    doc = copy.deepcopy(default_doc)
    mutate(doc)
    assert _error_for(tmp_path, doc).key_path == key_path


def test_non_convex_polygon_is_rejected(default_doc: dict) -> None:
    default_doc['obstacles'].append({'name': 'bowtie', 'kind': 'polygon',
                                     'points': [[0, 0], [1, 1], [1, 0], [0, 1]]})
    with pytest.raises(CellError) as info:
        cell_from_mapping(default_doc, 'x.yaml')
    assert info.value.key_path == 'obstacles[5].points'


def test_clockwise_polygon_is_normalised(default_doc: dict) -> None:
    default_doc['obstacles'].append({'name': 'block', 'kind': 'polygon',
                                     'points': [[0, 0], [0, 1], [1, 1], [1, 0]]})
    cell = cell_from_mapping(default_doc, 'x.yaml')
    assert cell.obstacles[-1].points == ((1.0, 0.0), (1.0, 1.0), (0.0, 1.0), (0.0, 0.0))


def test_invalid_yaml_and_unreadable_file(tmp_path: Path) -> None:
    bad = tmp_path / 'bad.yaml'
    bad.write_text('cell: [unclosed\n')
    with pytest.raises(CellError) as info:
        load_cell(bad)
    assert 'line' in info.value.key_path and 'YAML' in info.value.expected
    with pytest.raises(CellError) as info:
        load_cell(tmp_path / 'missing.yaml')
    assert 'missing.yaml' in str(info.value)


def test_yaml_tags_are_not_executed(tmp_path: Path) -> None:
    evil = tmp_path / 'evil.yaml'
    evil.write_text("cell: !!python/object/apply:os.system ['true']\n")
    with pytest.raises(CellError):
        load_cell(evil)


def test_defaults_are_derived() -> None:
    doc = {'cell': {'name': 'tiny'},
           'belts': [{'name': 'b', 'start': [0, 0], 'end': [1, 0], 'width': 0.2}],
           'part_types': [{'name': 'p', 'shape': 'box', 'length': 0.02, 'width': 0.01,
                           'height': 0.01, 'mass': 0.006}]}
    cell = cell_from_mapping(doc)
    part = cell.part_types[0]
    assert part.inertia == pytest.approx(0.006 * (0.02 ** 2 + 0.01 ** 2) / 12)
    assert cell.zones[0].policy == 'micro'
    assert cell.zones[0].region == pytest.approx((0.0, -0.1, 1.0, 0.1))
    radius = math.sqrt(0.02 * 0.01 / math.pi)
    assert cell.rho_max == pytest.approx(1 / (2 * math.sqrt(3) * radius ** 2))


def test_validate_verb_exit_codes(tmp_path: Path, default_doc: dict, capsys) -> None:
    assert cli_main(['validate']) == 0
    out = capsys.readouterr().out
    assert 'seed_test_rig' in out and 'deflector' in out and out.count('\n') == 2
    assert 'conveyor-twin plot default -o cell.png' in out
    default_doc['sources'][0]['part_type'] = 'bolt'
    path = _write(tmp_path, default_doc)
    assert cli_main(['validate', str(path)]) == 1
    err = capsys.readouterr().err
    assert str(path) in err and 'sources[0].part_type' in err and "'bolt'" in err


def test_validate_as_a_process(tmp_path: Path, default_doc: dict) -> None:
    del default_doc['belts'][0]['width']
    path = _write(tmp_path, default_doc)
    proc = subprocess.run([sys.executable, '-m', 'conveyor_twin.cli', 'validate', str(path)],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert 'belts[0].width' in proc.stderr
