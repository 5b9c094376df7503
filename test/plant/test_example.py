"""The example plant: every cell file is valid, and in one process parts go from the infeed
through the deflector cell and out of both outputs of the sorter, the ledger balanced."""

from pathlib import Path

import pytest

from conveyor_twin.cell.loader import load_cell
from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.runner import PlantRunner

EXAMPLE = Path(__file__).resolve().parents[2] / 'examples' / 'plant'


@pytest.mark.parametrize('name', ['infeed', 'deflector', 'sorter', 'buffer'])
def test_example_cells_are_valid_cells(name):
    cell = load_cell(EXAMPLE / f'{name}.yaml')
    assert cell.settings.step == 0.001


def test_the_deflector_cell_is_the_default_cell_fed_by_a_link():
    default, cell = load_cell(None), load_cell(EXAMPLE / 'deflector.yaml')
    assert cell.sources == () and default.sources
    assert cell.belts == default.belts and cell.obstacles == default.obstacles
    assert cell.sinks == default.sinks and cell.actuators == default.actuators


def test_parts_reach_both_buffers():
    runner = PlantRunner(load_plant(EXAMPLE / 'plant.yaml'))
    runner.run_to(20000)
    ledger = runner.ledger()
    assert ledger.residual == 0.0, ledger.text()
    assert ledger.links['sorter_left'].inserted > 0, ledger.text()
    assert ledger.links['sorter_right'].inserted > 0, ledger.text()
    assert runner.by_name['buffer_left'].twin.micro.sim.n > 0
