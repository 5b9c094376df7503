"""Foxglove layouts generated per cell and per plant name exactly the topics the view serves:
its scene, the density grid of each macro zone, its belts, barriers and diagnostics."""

import json
from pathlib import Path

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.cli import foxglove_layout as cli
from conveyor_twin.plant.loader import load_plant
from conveyor_twin.viz.foxglove_layout import (cell_layout, layout_topics, plant_layout,
                                               published_topics)
from conveyor_twin.viz.foxglove_plant import plant_topics
from conveyor_twin.viz.foxglove_view import density_zones, served_topics

ROOT = Path(__file__).resolve().parents[2]
SHIPPED_CELLS = [None] + sorted(str(p) for p in (ROOT / 'conveyor_twin/cell/examples')
                                .glob('*.yaml')) + sorted(
    str(p) for p in (ROOT / 'examples/plant').glob('*.yaml') if p.name != 'plant.yaml')
PLANT = ROOT / 'examples/plant/plant.yaml'


def _scene_topics(topics) -> set:
    return {t for t in topics if '/scene' in t}


@pytest.mark.parametrize('path', SHIPPED_CELLS, ids=lambda p: Path(p).name if p else 'default')
@pytest.mark.parametrize('namespace', ['', '/line1'])
def test_a_cell_layout_names_exactly_what_its_view_serves(path, namespace):
    cell = load_cell(path)
    layout = cell_layout(cell, namespace)
    served = set(served_topics(cell, namespace))
    read = layout_topics(layout)
    assert read <= served, read - served
    assert _scene_topics(read) == _scene_topics(served)  # the scene and every macro zone
    assert {f'{namespace}/scene/density/{zone}' for zone in density_zones(cell)} <= read
    assert published_topics(layout) == ({f'{namespace}/belt_command'} if cell.belts else set())
    text = json.dumps(layout)
    for thing in cell.belts + cell.light_barriers:
        assert thing.name in text


def test_the_multiscale_layout_shows_its_macro_zone():
    cell = load_cell(str(ROOT / 'conveyor_twin/cell/examples/multiscale.yaml'))
    topics = cell_layout(cell)['configById']['3D!scene']['topics']
    assert topics['/scene/density/bulk']['colorField'] == 'density'
    assert '/scene/density/belt' not in topics


def test_the_plant_layout_shows_every_cell_in_the_plant_frame():
    plant = load_plant(PLANT)
    layout = plant_layout(plant)
    served = set(plant_topics(plant))
    read = layout_topics(layout)
    assert read <= served, read - served
    assert _scene_topics(read) == _scene_topics(served)
    assert {f'/{c.namespace}/scene' for c in plant.cells} <= read
    assert layout['configById']['3D!scene']['followTf'] == plant.namespace
    assert published_topics(layout) == set()  # the plant view is read-only


def test_the_shipped_layouts_are_the_generated_ones(tmp_path):
    """docs/foxglove/layout.json is the default cell's, plant_layout.json the example
    plant's: regenerated with the command, they are unchanged."""
    for args, shipped in (([], 'layout.json'), ([str(PLANT)], 'plant_layout.json')):
        out = tmp_path / shipped
        assert cli.main(args + ['-o', str(out)]) == 0
        assert json.loads(out.read_text()) == json.loads(
            (ROOT / 'docs/foxglove' / shipped).read_text())


def test_a_bad_file_is_refused(tmp_path, capsys):
    assert cli.main([str(tmp_path / 'missing.yaml')]) == 2
    assert 'missing.yaml' in capsys.readouterr().err
