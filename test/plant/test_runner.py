"""The plant in one process: the ledger balances every step, ids are unique plant-wide,
reruns and both stepping orders give the same bits, a full link makes parts queue upstream,
a finished cell settles its upstream neighbour and steps no more."""

from pathlib import Path

import numpy as np
import pytest

from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.model import ID_RANGE
from conveyor_twin.plant.runner import PlantRunner

RES = Path(__file__).resolve().parents[1] / 'resources' / 'plant'
STEPS = 1500


@pytest.fixture(scope='module')
def plant():
    return load_plant(RES / 'chain.yaml')


def test_ledger_balances_and_ids_are_unique(plant):
    runner = PlantRunner(plant, check_balance=True)
    for _ in range(STEPS // 50):
        runner.step(50)
        ledger = runner.ledger()
        assert ledger.residual == 0.0, ledger.text()
        ids = [c.twin.micro.sim.parts_view().id for c in runner.cells]
        for k, cell_ids in enumerate(ids):
            assert np.all(cell_ids // ID_RANGE == k)
        allids = np.concatenate(ids)
        assert len(np.unique(allids)) == len(allids)
    ledger = runner.ledger()
    # parts crossed both links and left at the end of the line
    assert ledger.links['first_second'].inserted > 5 and ledger.left > 5, ledger.text()
    for name, k in ledger.links.items():
        cell = runner.by_name[plant.links[[x.name for x in plant.links].index(name)]
                              .target.cell]
        assert k.inserted == sum(e.inserted for e in cell.entries if e.link.name == name)
    assert ledger.entered == ledger.in_cells + ledger.in_links + ledger.left


def test_reruns_and_stepping_orders_are_bit_identical(plant):
    a, b, c = PlantRunner(plant), PlantRunner(plant), PlantRunner(plant)
    a.step(STEPS)
    b.step(STEPS)
    c.run_to(STEPS)
    assert a.state_hashes() == b.state_hashes() == c.state_hashes()
    assert a.ledger().as_dict() == c.ledger().as_dict()
    # cells really ran apart in run_to: the rule lets them (delays 40 and 30 steps)
    d = PlantRunner(plant)
    d.cells[0].step()
    assert d.cells[1].horizon() == 1 + 40 - 1 and d.cells[0].horizon() == 0 + 40


def test_a_full_link_holds_its_capacity_and_parts_queue_upstream(plant):
    runner = PlantRunner(plant)
    first = runner.by_name['first']
    first.twin.twin.commands.submit_belt('main', 0.0)     # the downstream belt stops
    runner.run_to(STEPS)
    ledger = runner.ledger()
    feed = ledger.links['feed_first']
    assert feed.held == 4 and feed.waiting == 4, ledger.text()   # capacity 4, all due
    feeder = runner.by_name['feeder'].twin.micro.sim
    exit_parts = np.count_nonzero(feeder.parts_view().x > 0.3)
    assert exit_parts >= 10                                       # the jam reaches upstream
    assert ledger.residual == 0.0


def test_a_cell_never_steps_past_what_its_neighbours_allow(plant):
    runner = PlantRunner(plant)
    first = runner.by_name['first']
    with pytest.raises(RuntimeError, match='may not compute step 41'):
        for _ in range(41):
            first.step()


def test_a_finished_cell_settles_its_upstream_neighbour_and_steps_no_more(plant):
    runner = PlantRunner(plant)
    runner.run_to(300)
    feeder, first, second = (runner.by_name[n] for n in ('feeder', 'first', 'second'))
    assert not (feeder.settled() or first.settled()) and second.settled()  # no exits
    second.finish()
    runner.exchange()
    assert first.settled() and not feeder.settled()
    first.finish()
    runner.exchange()
    assert feeder.settled()
    with pytest.raises(RuntimeError, match="'second' finished its run at step 300"):
        second.step()
    ledger = runner.ledger()
    assert ledger.residual == 0.0 and ledger.entered > 0
