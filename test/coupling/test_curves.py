"""Scale coupling on a curved line: hand-over, macro light barriers, ledger, auto tiles."""

from pathlib import Path
from typing import Dict, List

import numpy as np
import pytest
import yaml

from conveyor_twin.cell.loader import cell_from_mapping
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coupling.scale import ScaleCoupling
from conveyor_twin.coupling.tiles import slip_per_tile
from conveyor_twin.macro import MacroSim

L_LINE = Path(__file__).resolve().parents[2] / 'conveyor_twin/cell/examples/l_line.yaml'

# The bend of the L-shaped line (and a little of both straights) at the macro scale.
BEND_MACRO = [
    {'name': 'up', 'policy': 'micro', 'region': [0.0, -0.25, 1.5, 0.25], 'resolution': 0.02},
    {'name': 'bend', 'policy': 'macro', 'region': [1.5, -0.26, 2.86, 1.2], 'resolution': 0.02},
    {'name': 'down', 'policy': 'micro', 'region': [2.34, 1.2, 2.86, 2.65], 'resolution': 0.02}]


def _l_line(rate: float, zones: List[Dict] = None, barriers: List[str] = None):
    d = yaml.safe_load(L_LINE.read_text())
    d['sources'][0]['rate'] = rate
    if barriers is not None:
        d['light_barriers'] = [b for b in d['light_barriers'] if b['name'] in barriers]
    if zones is not None:
        d['zones'] = zones
    return cell_from_mapping(d)


def _twin(cell, seed: int = 1):
    built = build_twin(cell, seed=seed)
    coupling = built.twin.stages[-1]
    assert isinstance(coupling, ScaleCoupling)
    coupling.check = True   # raises at the first step whose ledger does not balance
    return built.twin, built.micro, built.macro, coupling


@pytest.fixture(scope='module')
def bend_run():
    """12 s of 8 parts/s through the L-shaped line with its bend macro, ledger checked every
    step; the mass that passed the beam behind the bend is recorded along the way."""
    twin, micro, macro, coupling = _twin(_l_line(8.0, BEND_MACRO))
    twin.step(12000)
    return twin, micro, macro, coupling


def test_hand_over_across_a_curve_conserves_every_part(bend_run) -> None:
    twin, micro, macro, coupling = bend_run
    led = coupling.ledger()
    assert led['captured'] > 60 and led['released'] > 40 and led['left'] > 20
    assert coupling.max_residual <= 1e-9
    total = led['micro'] + led['macro'] + led['pending'] + led['left']
    assert total == pytest.approx(led['entered'], abs=1e-9)
    assert led['type_residual'] == pytest.approx(0.0, abs=1e-9)
    # What the curve released rides the outfeed (+y at 0.5 m/s), on the outfeed.
    v = micro.sim.parts_view()
    out = (v.y > 1.35) & (v.y < 2.4)
    assert out.sum() > 5
    assert np.all((v.x[out] > 2.4) & (v.x[out] < 2.8))
    assert np.allclose(v.vy[out], 0.5, atol=0.05) and np.allclose(v.vx[out], 0.0, atol=0.05)
    # Nothing was left off the belt in the bend's grid: the arcs hold the density.
    (sim,) = macro.grids
    assert float(sim.density[sim._belt_idx < 0].sum()) == 0.0


def test_macro_light_barriers_count_the_flux_through_and_behind_a_curve(bend_run) -> None:
    twin, micro, macro, coupling = bend_run
    (sim,) = macro.grids
    by_index = {b.index: b for b in coupling.barriers}
    names = [b.name for b in twin.cell.light_barriers]
    before, after = by_index[names.index('lb_before')], by_index[names.index('lb_after')]
    xs, ys = sim.grid.centres()
    h2 = sim.resolution ** 2
    captured = coupling.ledger()['captured']
    # lb_before (x = 1.8, on the infeed) and lb_after (y = 0.8, on the outfeed behind the
    # bend): each has counted the mass that is no longer upstream of it.
    passed_before = captured - float(sim.density[xs < 1.8].sum()) * h2
    upstream_after = (ys < 0.8) & ~((xs > 2.4) & (ys > 0.6))   # infeed and curve
    passed_after = captured - float(sim.density[upstream_after].sum()) * h2
    assert passed_after > 30
    assert before.crossings == pytest.approx(passed_before, rel=0.05, abs=1.0)
    assert after.crossings == pytest.approx(passed_after, rel=0.05, abs=1.0)
    # Each crossing is a virtual part: at most two edges each (fewer where the parts follow
    # closer than their length and the beam stays blocked).
    counts = micro.barrier_edge_count()
    for barrier in (before, after):
        assert 10 < counts[barrier.index] <= 2 * int(np.ceil(barrier.crossings)) + 1


def test_slip_on_a_curve_is_measured_against_the_local_rotation() -> None:
    cell = _l_line(3.0)
    sim = MacroSim(cell, 'line')
    bend = cell.belts[1]
    rng = np.random.default_rng(3)
    pts = []
    while len(pts) < 200:
        p = (rng.uniform(2.0, 2.8), rng.uniform(-0.2, 0.6))
        if bend.contains(p):
            pts.append(p)
    x, y = np.array(pts).T
    riding = np.array([bend.surface_velocity(p, bend.speed) for p in pts])
    tc = 5
    nty, ntx = -(-sim.ny // tc), -(-sim.nx // tc)
    slip = np.zeros((nty, ntx))
    slip_per_tile(x, y, riding[:, 0], riding[:, 1], len(x), sim.origin_x, sim.origin_y,
                  sim.resolution, sim.cell_velocity, tc, slip)
    # Parts riding with the curve slip by the cell's size only (|omega| h / sqrt(2) / |v|).
    assert slip.sum() / len(x) < 0.04
    slip[:] = 0.0
    straight = np.tile([0.5, 0.0], (len(x), 1))   # as if the belt ran straight on
    slip_per_tile(x, y, straight[:, 0], straight[:, 1], len(x), sim.origin_x, sim.origin_y,
                  sim.resolution, sim.cell_velocity, tc, slip)
    assert slip.sum() / len(x) > 0.3


def test_auto_tiles_on_a_curve_turn_macro_in_a_queue_and_back() -> None:
    # The L-shaped line (one auto zone) at 8 parts/s (40 parts/m^2 of free flow, below both
    # thresholds), without the beam behind the bend (its sensor window would keep the tiles
    # at the bend's end micro). With the outfeed stopped the parts queue from its start back
    # into the bend: the bend's tiles go macro; running again, the queue dissolves and they
    # come back micro. Every part is accounted for at every step.
    twin, micro, macro, coupling = _twin(_l_line(8.0, barriers=['lb_before']))
    tiles = coupling.regions[0].tiles
    sim = coupling.regions[0].sim
    tc, h = tiles.tc, sim.resolution
    xt = sim.origin_x + (np.arange(tiles.ntx) + 0.5) * tc * h
    yt = sim.origin_y + (np.arange(tiles.nty) + 0.5) * tc * h
    xg, yg = np.meshgrid(xt, yt)
    bend = twin.cell.belts[1]
    on_bend = np.array([[bend.contains((x, y)) for x, y in zip(rx, ry)]
                        for rx, ry in zip(xg, yg)])
    twin.step(3000)
    assert not (tiles.macro & on_bend).any(), 'free flow on the bend stays micro'
    twin.commands.submit_belt('outfeed', 0.0)
    twin.step(10000)
    assert (tiles.macro & on_bend).any(), 'the queue in the bend went macro'
    switches = tiles.switches
    twin.commands.submit_belt('outfeed', 0.5)
    twin.step(10000)
    assert tiles.switches > switches
    assert not (tiles.macro & on_bend).any(), 'the bend is back to micro'
    assert coupling.max_residual <= 1e-9
