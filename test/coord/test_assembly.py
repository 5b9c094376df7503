"""The composed assembly: what :func:`build_twin` wires (the split roles: test/split)."""

import numpy as np
import pytest
import yaml

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.loader import cell_from_mapping, default_cell_text
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.requests import check_spawn
from conveyor_twin.coord.stages import MacroStage, MicroStage
from conveyor_twin.coupling.scale import ScaleCoupling

MID_MACRO = [{'name': 'up', 'policy': 'micro', 'region': [0.0, -0.25, 1.5, 0.25]},
             {'name': 'mid', 'policy': 'macro', 'region': [1.5, -0.25, 2.5, 0.25]},
             {'name': 'down', 'policy': 'micro', 'region': [2.5, -0.25, 6.0, 0.25]}]


def mid_macro_cell():
    d = yaml.safe_load(default_cell_text())
    d['sources'][0]['rate'] = 200.0
    d['zones'] = MID_MACRO
    return cell_from_mapping(d)


def test_composed_steps_micro_macro_then_the_coupling_built_with_both() -> None:
    built = build_twin(load_cell(), seed=4)
    micro, macro, coupling = built.twin.stages
    assert isinstance(micro, MicroStage) and isinstance(macro, MacroStage)
    assert isinstance(coupling, ScaleCoupling)
    assert (built.micro, built.macro, built.coupling) == (micro, macro, coupling)
    assert coupling.micro_stage is micro and coupling.macro_stage is macro
    # the micro stage reads the barriers of macro zones from the holder the coupling fills
    assert micro.macro_barriers is coupling.zone_barriers
    assert not hasattr(micro, 'coupling') and not hasattr(macro, 'coupling')


def test_composed_publishes_the_barriers_of_macro_zones_from_the_density() -> None:
    built = build_twin(mid_macro_cell(), seed=1)
    assert [b.index for b in built.coupling.barriers] == [0]
    built.step(8000)  # the first parts reach the beam (x = 2.0) after about 4 s
    macro_count = int(built.coupling.barriers[0].edge_count)
    assert macro_count > 0
    assert int(built.micro.barrier_edge_count()[0]) == macro_count
    assert built.micro.sim.edge_count[0] == 0  # no micro part is ever seen in a macro zone


def test_macro_counters_carry_the_ledger_only_where_the_hand_over_runs() -> None:
    coupled = build_twin(mid_macro_cell(), seed=1)
    coupled.step(500)
    counters = coupled.macro_counters()
    assert abs(counters['balance_residual']) <= 1e-9 and counters['balance_entered'] > 0
    assert not any(k.startswith('balance_') for k in build_twin(load_cell(), seed=1)
                   .macro_counters())
    assert not any(k.startswith('balance_') for k in coupled.micro_counters())


def test_spawn_places_a_checked_request_and_the_part_check_sees_it() -> None:
    cell = load_cell()
    built = build_twin(cell, seed=1)
    request = check_spawn(cell, cell.part_types[0].name, [1.0], [0.0], [])
    ids = built.spawn(request)
    assert list(built.micro.parts()[0]) == list(ids)
    assert built.holds_part(int(ids[0])) and not built.holds_part(int(ids[0]) + 1000)
    with pytest.raises(ValueError, match='nothing placed'):
        built.spawn(request)  # the same pose again overlaps the first part


def test_reset_rebinds_the_coupling_and_its_barriers() -> None:
    built = build_twin(mid_macro_cell(), seed=1)
    built.step(800)
    before = built.coupling.barriers[0]
    built.twin.reset(seed=5)
    assert built.coupling.barriers[0] is not before
    assert built.coupling.barriers[0].sim is built.macro.grids[0]
    assert np.all(built.micro.barrier_edge_count() == 0)
