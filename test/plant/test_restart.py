"""A restarted cell in one process (:meth:`PlantRunner.restart`): with a capacity on every link,
a run of fixed duration finishes whichever cell restarts (upstream, middle, downstream), and
the ledger balances with what died with the ended run."""

from pathlib import Path

import pytest
import yaml

from conveyor_twin.plant.loader import plant_from_mapping
from conveyor_twin.plant.runner import PlantRunner

RES = Path(__file__).resolve().parents[1] / 'resources' / 'plant'
KILLED_AT = 1500    # steps
END = 4000          # steps: the fixed duration of the run


def capped_chain():
    """The test chain with a capacity on both links."""
    data = yaml.safe_load((RES / 'chain.yaml').read_text())
    for link in data['links']:
        link['capacity'] = 3
    return plant_from_mapping(data, str(RES / 'chain.yaml'), RES)


@pytest.fixture(scope='module')
def plant():
    return capped_chain()


@pytest.mark.parametrize('cell', ['feeder', 'first', 'second'])
def test_a_restarted_cell_on_capacity_links_lets_a_fixed_duration_run_finish(plant, cell):
    runner = PlantRunner(plant)
    runner.run_to(KILLED_AT)
    assert runner.ledger().in_links > 0, runner.ledger().text()
    runner.restart(cell, run=2)
    runner.run_to(END, finish=True)   # deadlocked before: a peer finished at its last step
    assert {c.name: c.step_index for c in runner.cells} == {
        'feeder': END, 'first': END, 'second': END}
    assert all(c.finished and c.settled() for c in runner.cells)
    ledger = runner.ledger()
    assert ledger.residual == 0.0, ledger.text()
    assert [r.cell for r in runner.ended] == [cell]
    assert ledger.left > 0 and ledger.lost > 0, ledger.text()


def test_a_capacity_link_still_gates_its_upstream_cell_until_the_entry_finishes(plant):
    runner = PlantRunner(plant)
    runner.run_to(KILLED_AT)
    runner.restart('feeder', run=2)
    feeder, first = runner.by_name['feeder'], runner.by_name['first']
    runner.exchange()                 # the new run and its entry cell find each other
    runner.exchange()
    delay = plant.links[0].delay_steps
    # the new run counts from 0, the entry follows it from its own step KILLED_AT
    assert first.step_index == KILLED_AT and feeder.horizon() == delay
    while feeder.may_step():
        feeder.step()
    runner.exchange()
    assert feeder.step_index == delay and not feeder.may_step()
    first.finish()
    runner.exchange()
    assert feeder.horizon() > END     # a finished entry inserts nothing more


def test_a_restart_needs_a_new_run_id(plant):
    runner = PlantRunner(plant)
    with pytest.raises(ValueError, match='another id than 0'):
        runner.restart('first', run=0)


@pytest.mark.parametrize('cell', ['infeed', 'sorter'])
def test_the_example_plant_finishes_after_a_restart(cell):
    from conveyor_twin.plant.loader import load_plant
    example = Path(__file__).resolve().parents[2] / 'examples' / 'plant' / 'plant.yaml'
    runner = PlantRunner(load_plant(example))    # every link has a capacity
    runner.run_to(2000)
    runner.restart(cell, run=2)
    runner.run_to(6000, finish=True)
    assert all(c.step_index == 6000 and c.finished for c in runner.cells)
    assert runner.ledger().residual == 0.0, runner.ledger().text()
