"""Light barriers: edge times interpolated inside the step, part ids, counts."""

import pytest

from conveyor_twin.cell.model import LightBarrier
from conveyor_twin.micro import MicroSim
from test.micro.conftest import box, disc, make_cell


@pytest.mark.parametrize('x0, speed', [(0.2, 0.5), (0.2137, 0.73), (0.31, 1.9)])
def test_disc_edge_times_match_distance_over_speed(x0, speed):
    r = 0.005
    xb = 0.5
    barrier = LightBarrier(name='lb', start=(xb, -0.25), end=(xb, 0.25), height=0.005)
    cell = make_cell(part_types=(disc(radius=r),), speed=speed, light_barriers=(barrier,))
    sim = MicroSim(cell, seed=0)
    (pid,) = sim.spawn(0, x0, 0.03, 0.0, vx=speed)
    sim.step(int((xb - x0 + 0.05) / speed / cell.settings.step) + 5)
    ev = sim.drain_events()
    assert len(ev) == 2 and list(ev.blocked) == [True, False]
    assert list(ev.part_id) == [pid, pid]
    # blocked while the centre is within r of the beam
    t_in = (xb - r - x0) / speed
    t_out = (xb + r - x0) / speed
    assert abs(ev.time[0] - t_in) < 1e-4
    assert abs(ev.time[1] - t_out) < 1e-4
    assert abs(ev.time[0] - t_in) < 1e-7            # constant speed: exact up to bisection
    assert sim.edge_count[0] == 2 and not sim.blocked[0]
    assert len(sim.drain_events()) == 0


def test_box_and_short_part():
    barrier = LightBarrier(name='lb', start=(0.5, -0.25), end=(0.5, 0.25), height=0.005)
    low = disc(height=0.004, name='low')                  # below the beam: never seen
    cell = make_cell(part_types=(box(length=0.04, width=0.02), low), speed=0.5,
                     light_barriers=(barrier,))
    sim = MicroSim(cell, seed=0)
    (pid,) = sim.spawn(0, 0.3, 0.0, 0.0, vx=0.5)         # long axis along x
    sim.spawn(1, 0.3, 0.1, 0.0, vx=0.5)
    sim.step(600)
    ev = sim.drain_events()
    assert list(ev.part_id) == [pid, pid]
    assert ev.time[0] == pytest.approx((0.5 - 0.02 - 0.3) / 0.5, abs=1e-4)
    assert ev.time[1] == pytest.approx((0.5 + 0.02 - 0.3) / 0.5, abs=1e-4)


def test_two_parts_first_in_last_out():
    barrier = LightBarrier(name='lb', start=(0.5, -0.25), end=(0.5, 0.25), height=0.005)
    cell = make_cell(speed=0.5, light_barriers=(barrier,))
    sim = MicroSim(cell, seed=0)
    a, b = sim.spawn(0, [0.3, 0.302], [0.1, -0.1], 0.0, vx=0.5)
    sim.step(600)
    ev = sim.drain_events()
    assert list(ev.blocked) == [True, False]
    assert ev.part_id[0] == b and ev.part_id[1] == a     # b is ahead, a leaves last
