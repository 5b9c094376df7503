"""MicroSim's interface: spawn/remove, ids, sinks, region outbox, sources, actuators."""

from dataclasses import replace

import numpy as np
import pytest

from conveyor_twin.cell.model import Actuator, Sink, Source
from conveyor_twin.micro import MicroSim, SpawnBoundsError, SpawnOverlapError
from test.micro.conftest import disc, make_cell, wall


def test_spawn_refuses_overlap_and_ids_are_never_reused():
    cell = make_cell(obstacles=(wall('w', (0.5, -0.25), (0.5, 0.25), thickness=0.01),))
    sim = MicroSim(cell, seed=0)
    assert list(sim.spawn(0, [0.1, 0.2], 0.0, 0.0)) == [1, 2]
    with pytest.raises(SpawnOverlapError, match=r'entries \[1\]'):
        sim.spawn(0, [0.3, 0.205], 0.0, 0.0)               # second overlaps part 2
    assert sim.n == 2 and sim.entered == 2
    ids = sim.spawn(0, [0.3, 0.498, 0.205], 0.0, 0.0, strict=False)   # wall, part
    assert list(ids) == [3, 0, 0]
    removed = sim.remove([2])
    assert list(removed.id) == [2] and removed.x[0] == 0.2
    assert list(sim.parts_view().id) == [1, 3]              # order kept
    assert list(sim.spawn(0, 0.2, 0.0, 0.0)) == [4]
    assert sim.counters()['removed'] == 1


def test_spawn_refuses_parts_outside_the_cell():
    cell = make_cell(sinks=(Sink(name='bin', region=(0.8, -0.6, 1.0, -0.3)),))
    sim = MicroSim(cell, seed=0)
    assert sim.extent == pytest.approx((0.0, -0.6, 2.0, 0.25))  # the belt and the bin
    with pytest.raises(SpawnBoundsError, match=r'entries \[1, 2\] lie outside the cell '
                       r'\(e\.g\. entry 1 at x = 1e\+06 m, y = 1e\+06 m; the cell spans '
                       r'x 0\.\.2 m, y -0\.6\.\.0\.25 m\); nothing placed'):
        sim.spawn(0, [0.5, 1e6, -0.1], [0.0, 1e6, 0.0], 0.0)
    for x, y in ((2.01, 0.0), (0.5, 0.3), (np.nan, 0.0), (0.5, np.inf)):
        with pytest.raises(SpawnBoundsError, match=r'entries \[0\] lie outside'):
            sim.spawn(0, x, y, 0.0)
    with pytest.raises(SpawnBoundsError, match=r'entries \[0\] have a yaw or velocity'):
        sim.spawn(0, 0.5, 0.0, np.nan)
    assert sim.n == 0 and sim.entered == 0                  # nothing placed
    # not strict: the entries outside get id 0, the others are placed; the bin is in the cell
    ids = sim.spawn(0, [0.5, 1e6, 0.9], [0.0, 0.0, -0.45], 0.0, strict=False)
    assert list(ids) == [1, 0, 2] and sim.n == 2


def test_sinks_count_and_balance():
    cell = make_cell(speed=1.0, sinks=(Sink(name='end', region=(1.9, -0.3, 2.1, 0.3)),))
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, np.linspace(0.1, 0.5, 5), 0.0, 0.0, vx=1.0)
    sim.step(2000)
    assert list(sim.left) == [5] and sim.n == 0
    c = sim.counters()
    assert c['entered'] == c['in_flight'] + c['left'] + c['handed_over'] + c['removed']


def test_region_moves_leaving_parts_to_the_outbox():
    cell = make_cell(speed=0.5)
    sim = MicroSim(cell, seed=0, region=(0.0, -0.25, 1.0, 0.25))
    sim.spawn(0, [0.9, 0.5], 0.0, 0.0, vx=0.5)
    sim.step(300)                                           # first crosses x = 1.0
    out = sim.drain_outbox()
    assert list(out.id) == [1] and out.x[0] > 1.0 and out.vx[0] == pytest.approx(0.5)
    assert sim.n == 1 and len(sim.drain_outbox()) == 0


def test_sources_spawn_deterministically_without_overlap():
    src = Source(name='s', part_type='disc', region=(0.05, -0.1, 0.1, 0.1), rate=200.0,
                 pattern='poisson', max_parts=60)
    cell = make_cell(speed=0.0, sources=(src,))
    runs = []
    for _ in range(2):
        sim = MicroSim(cell, seed=5)
        sim.step(2000)
        runs.append(sim.state_bytes())
        v = sim.parts_view()
        d = np.hypot(v.x[:, None] - v.x, v.y[:, None] - v.y) + np.eye(sim.n)
        assert d.min() > 2 * 0.005 - 2e-4                  # never spawned overlapping
    assert runs[0] == runs[1]
    assert sim.entered <= 60


def test_pusher_imparts_an_impulse_and_stopper_holds():
    pusher = Actuator(name='p', kind='pusher', base=(0.5, 0.2), axis=(0.0, -1.0), length=0.02,
                      width=0.1, position_range=(0.0, 0.4), max_speed=0.8, initial_position=0.0)
    stopper = Actuator(name='st', kind='stopper', base=(1.0, 0.0), axis=(0.0, 1.0),
                       length=0.5, width=0.01, position_range=(0.0, 0.008), max_speed=0.1,
                       initial_position=0.0, engage_height=0.004)
    cell = make_cell(part_types=(disc(restitution=0.0),), speed=0.0,
                     actuators=(pusher, stopper))
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.5, 0.0, 0.0)
    sim.set_actuator_target(0, 0.4)
    sim.step(200)
    assert sim.actuator_position[0] == pytest.approx(0.16)
    sim.step(200)
    # paddle face at y = 0.2 - 0.32 - 0.01: the part is ahead of it, pushed across
    v = sim.parts_view()
    assert v.y[0] <= 0.2 - 0.32 - 0.01 - 0.005 + 1e-3
    assert v.vy[0] < 0.0
    # stopper raised: a part carried by the belt stops in front of it
    sim2 = MicroSim(replace(cell, belts=(replace(cell.belts[0], speed=0.5),)), seed=0)
    sim2.set_actuator_target(1, 0.008)
    sim2.step(100)
    sim2.spawn(0, 0.8, 0.0, 0.0, vx=0.5)
    sim2.step(1500)
    v = sim2.parts_view()
    assert v.x[0] == pytest.approx(1.0 - 0.005 - 0.005, abs=3e-4)
    sim2.set_actuator_target(1, 0.0)
    sim2.step(1000)
    assert sim2.parts_view().x[0] > 1.2
