"""The broad phase's neighbour list: kept or rebuilt, the contacts (and states) are the same."""

from conveyor_twin.bench import micro as bench
from conveyor_twin.micro import MicroSim
from conveyor_twin.micro.contacts import NB_VALID


def run_pair(a: MicroSim, b: MicroSim, steps: int) -> None:
    """Step ``a`` normally and ``b`` with its neighbour list thrown away before every step."""
    for _ in range(steps):
        a.step(1)
        b._nbr[NB_VALID] = 0
        b.step(1)
        assert a.state_bytes() == b.state_bytes()


def test_kept_list_equals_fresh_search_in_flow(default_cell):
    a = MicroSim(default_cell, seed=3)
    b = MicroSim(default_cell, seed=3)
    a.set_actuator_target(0, 0.3)
    b.set_actuator_target(0, 0.3)
    run_pair(a, b, 1500)
    assert a.n > 20
    assert a.neighbour_builds < b.neighbour_builds


def test_kept_list_equals_fresh_search_in_a_jam():
    a = bench.jammed_sim(300, 600)
    b = bench.jammed_sim(300, 600)
    builds = a.neighbour_builds
    run_pair(a, b, 300)
    # the jam has settled: the list lives for many steps
    assert a.neighbour_builds - builds < 30
    assert bench.max_penetration(a) < 0.1 * a.cell.part_types[0].radius
