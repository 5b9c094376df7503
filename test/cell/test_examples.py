"""The example cells shipped beside the default cell load and do what they are for.

Each runs in the core (no ROS) for a few seconds of simulated time: the multi-scale cell turns
parts into density and back, the sorting cell sends each part type to its own output under a
controller that reads only the light barriers, the merge cell carries parts from both belts to
the exit. The part balance is exact in every run.
"""

from pathlib import Path
from typing import Dict, Tuple

import numpy as np
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.stages import MicroStage
from conveyor_twin.coord.twin import Twin

EXAMPLES = Path(__file__).resolve().parents[2] / 'conveyor_twin' / 'cell' / 'examples'
NAMES = ('multiscale.yaml', 'sorting.yaml', 'merge.yaml')
# Diverter positions of the sorting cell [rad]: across the belt (to the side belt), open.
DIVERT, PASS = 0.9, 0.0


def _micro_twin(name: str) -> Tuple[Twin, MicroStage]:
    cell = load_cell(EXAMPLES / name)
    micro = MicroStage(cell, cell.settings.seed)
    return Twin(cell, seed=cell.settings.seed, stages=[micro]), micro


def _track(micro: MicroStage, last: Dict[int, Tuple[int, float, float]],
           gone: Dict[int, Tuple[int, float, float]]) -> None:
    """Remember each part's type and last position; move parts no longer present to ``gone``."""
    v = micro.sim.parts_view()
    present = set(v.id.tolist())
    for pid in [p for p in last if p not in present]:
        gone[pid] = last.pop(pid)
    for pid, t, x, y in zip(v.id.tolist(), v.part_type.tolist(), v.x.tolist(), v.y.tolist()):
        last[pid] = (t, x, y)


def _assert_micro_balance(micro: MicroStage) -> None:
    c = micro.sim.counters()
    assert c['entered'] == c['in_flight'] + c['left'] + c['handed_over'] + c['removed']
    assert c['handed_over'] == 0 and c['removed'] == 0


@pytest.mark.parametrize('name', NAMES)
def test_example_cell_is_packaged_beside_the_default_cell(name: str) -> None:
    assert (EXAMPLES / name).is_file()
    cell = load_cell(EXAMPLES / name)
    assert cell.settings.name and cell.sources and cell.sinks


def test_multiscale_cell_shows_density_early_and_conserves_every_part() -> None:
    cell = load_cell(EXAMPLES / 'multiscale.yaml')
    assert [z.policy for z in cell.zones] == ['macro']
    built = build_twin(cell, seed=cell.settings.seed, check_balance=True)
    micro, macro, coupling, twin = built.micro, built.macro, built.coupling, built.twin
    assert coupling.enabled and coupling.check  # ledger checked every step: BalanceError
    twin.step(1500)
    grid = macro.grids[0]
    led = coupling.ledger()
    assert led['macro'] > 10.0, led                       # density after 1.5 s
    assert float(grid.region_parts(cell.zones[0].region)) > 10.0
    assert micro.sim.n > 0                                # parts still fed as rigid bodies
    twin.step(6000)
    led = coupling.ledger()
    assert led['released'] > 50.0, led                    # parts back as rigid bodies
    assert led['left'] > 20.0, led                        # and out through the exit
    assert int(micro.sim.left[0]) > 20
    assert abs(led['residual']) < 1e-9 and abs(led['type_residual']) < 1e-9
    assert coupling.max_residual < 1e-9


def test_sorting_cell_sends_each_part_type_to_its_output() -> None:
    twin, micro = _micro_twin('sorting.yaml')
    names = [b.name for b in twin.cell.light_barriers]
    any_beam, tall_beam = names.index('lb_any'), names.index('lb_tall')
    types = [p.name for p in twin.cell.part_types]
    disc, box = types.index('disc'), types.index('box')
    last: Dict[int, Tuple[int, float, float]] = {}
    gone: Dict[int, Tuple[int, float, float]] = {}
    for _ in range(16000):
        twin.step(1)
        barrier, blocked, _, _ = micro.edges()
        rising = set(barrier[blocked].tolist())
        if any_beam in rising:
            # The controller: a part on the low beam that also blocks the high one is a box.
            tall = bool(micro.barrier_blocked()[tall_beam])
            twin.commands.submit_actuator('diverter', DIVERT if tall else PASS)
        _track(micro, last, gone)
    sinks = [s.name for s in twin.cell.sinks]
    left = dict(zip(sinks, micro.sim.left.tolist()))
    by_type: Dict[int, set] = {disc: set(), box: set()}
    for t, x, y in gone.values():
        by_type[t].add('side_out' if y > 0.5 else 'end_out')
    assert by_type[disc] == {'end_out'}, (by_type, left)
    assert by_type[box] == {'side_out'}, (by_type, left)
    assert left['end_out'] >= 2 and left['side_out'] >= 2, left
    assert left['end_out'] + left['side_out'] == len(gone)
    _assert_micro_balance(micro)


def test_sorting_cell_without_a_controller_sends_everything_to_the_end() -> None:
    twin, micro = _micro_twin('sorting.yaml')
    twin.step(14000)
    left = dict(zip([s.name for s in twin.cell.sinks], micro.sim.left.tolist()))
    assert left['end_out'] >= 4 and left['side_out'] == 0, left
    _assert_micro_balance(micro)


def test_merge_cell_carries_parts_from_both_belts_to_the_exit() -> None:
    twin, micro = _micro_twin('merge.yaml')
    types = [p.name for p in twin.cell.part_types]
    last: Dict[int, Tuple[int, float, float]] = {}
    gone: Dict[int, Tuple[int, float, float]] = {}
    for _ in range(12):
        for _ in range(1000):
            twin.step(1)
            _track(micro, last, gone)
    out = np.bincount([t for t, _, _ in gone.values()], minlength=len(types))
    assert out[types.index('main_part')] >= 5, out
    assert out[types.index('side_part')] >= 5, out
    assert all(x > 3.8 for _, x, _ in gone.values())      # every part left through the exit
    assert int(micro.sim.left[0]) == len(gone)
    edges = micro.barrier_edge_count().astype(int).tolist()
    assert all(e > 0 for e in edges), edges                # both feeds and the exit seen
    _assert_micro_balance(micro)
