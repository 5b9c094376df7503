"""The impulse solver converges: simultaneous impacts keep restitution, friction stays in the
Coulomb cone, speculative contacts stop fast parts where they meet, momentum is kept."""

import math

import numpy as np
import pytest

from conveyor_twin.cell.model import Actuator
from conveyor_twin.micro import MicroSim
from conveyor_twin.micro.contacts import CT_DEPTH, CT_LN, CT_LT, CT_MU_K, CT_MU_S
from test.micro.conftest import disc, make_cell, wall

R = 0.005
D = 2 * R


def kinetic_energy(sim):
    v = sim.parts_view()
    pt = sim.cell.part_types[0]
    return 0.5 * pt.mass * float(np.sum(v.vx ** 2 + v.vy ** 2)) + 0.5 * pt.inertia * float(
        np.sum(v.wz ** 2))


def elastic_cell(**kw):
    """A frictionless belt at rest under frictionless, perfectly elastic discs."""
    return make_cell(part_types=(disc(restitution=1.0),), friction=0.0, **kw)


def billiard(gap):
    """A rack of 15 discs (rows 1..5, ``gap`` [m] between neighbours) and a striker at 1 m/s."""
    sim = MicroSim(elastic_cell(), seed=0)
    pitch = D + gap
    for row in range(5):
        for k in range(row + 1):
            sim.spawn(0, 0.6 + row * pitch * math.sqrt(3) / 2, (k - row / 2) * pitch, 0.0)
    sim.spawn(0, 0.45, 0.0, 0.0, vx=1.0)
    return sim


# the targets' centres: 1e-7 m more than a radius off the axis (side by side, not overlapping)
TARGET_Y = R + 1e-7


def three_body(v0=0.5):
    """A striker moving +x at ``v0`` hits two side-by-side targets at once."""
    sim = MicroSim(elastic_cell(), seed=0)
    cos = math.sqrt(D * D - TARGET_Y ** 2)
    sim.spawn(0, 0.5, 0.0, 0.0, vx=v0)
    sim.spawn(0, 0.53 + cos, TARGET_Y, 0.0)
    sim.spawn(0, 0.53 + cos, -TARGET_Y, 0.0)
    return sim


def three_body_answer(v0):
    """Return the hard-disc answer: (striker vx, targets' speed) with e = 1, equal masses: the
    impulse ``j`` along each line of centres (``cos`` to the axis) reverses both approach
    speeds, ``j - (v0 - 2 j cos) cos = v0 cos``."""
    c = math.sqrt(D * D - TARGET_Y ** 2) / D
    j = 2 * c * v0 / (1 + 2 * c * c)
    return v0 - 2 * j * c, j


def gas(packing, seed=1):
    """Elastic discs at ``packing`` area fraction in a 0.2 m square of elastic walls."""
    side = 0.2
    x0, y0 = 0.5, -0.1
    walls = [wall(f'w{k}', a, b, restitution=1.0, friction=0.0) for k, (a, b) in enumerate(
        [((x0, y0), (x0 + side, y0)), ((x0 + side, y0), (x0 + side, y0 + side)),
         ((x0 + side, y0 + side), (x0, y0 + side)), ((x0, y0 + side), (x0, y0))])]
    sim = MicroSim(elastic_cell(obstacles=walls, capacity=512), seed=0)
    n = int(packing * side * side / (math.pi * R * R))
    rng = np.random.default_rng(seed)
    pitch = side / math.ceil(math.sqrt(n) + 1)
    k = 0
    for gy in range(1, 40):
        for gx in range(1, 40):
            if k < n and gx * pitch < side - R and gy * pitch < side - R:
                v = rng.normal(scale=0.3, size=2)
                sim.spawn(0, x0 + gx * pitch, y0 + gy * pitch, 0.0, vx=v[0], vy=v[1])
                k += 1
    assert sim.n == n
    return sim


def queue_pile(speed, rows=3, **kw):
    """A lane three discs wide blocked by a wall; a queue at rest against it and discs arriving
    at ``speed`` on a belt running at ``speed``."""
    lane = 3 * D + 3e-3
    walls = (wall('side_a', (0.0, -lane / 2), (1.2, -lane / 2)),
             wall('side_b', (0.0, lane / 2), (1.2, lane / 2)),
             wall('stop', (1.0, -lane / 2), (1.0, lane / 2)))
    pt = disc(restitution=0.3, mu_s=0.3, mu_k=0.2)
    sim = MicroSim(make_cell(part_types=(pt,), obstacles=walls, speed=speed, **kw), seed=0)
    for row in range(10):
        for k in range(3):
            sim.spawn(0, 1.0 - R - 1e-4 - row * (D + 1e-4), (k - 1) * (D + 2e-4), 0.0)
    rng = np.random.default_rng(5)
    for row in range(rows * 5):
        shift = rng.uniform(-1e-3, 1e-3)      # rows off the lane's axis: oblique contacts
        for k in range(3):
            sim.spawn(0, 0.55 - row * (D + 2e-3), (k - 1) * (D + 2e-4) + shift, 0.0, vx=speed)
    return sim


def deepest_overlap(sim):
    """Return the deepest overlap of the last substep's contacts [m] (0 if none)."""
    nc = int(sim._prev[-1, 0])
    return float(max(sim._ct[:nc, CT_DEPTH].max(initial=0.0), 0.0))


def test_three_body_impact_is_symmetric_and_matches_the_hard_disc_answer():
    sim = three_body()
    sim.step(100)
    v = sim.parts_view()
    striker, target = three_body_answer(0.5)
    assert abs(v.vy[0]) <= 1e-9
    assert abs(v.vx[1] - v.vx[2]) <= 1e-9 and abs(v.vy[1] + v.vy[2]) <= 1e-9
    assert v.vx[0] == pytest.approx(striker, abs=0.02 * abs(striker))
    assert math.hypot(v.vx[1], v.vy[1]) == pytest.approx(target, rel=0.02)


def funnel(gap, speed=0.3):
    """Discs with friction carried by a belt into a funnel of two walls ending ``gap`` apart."""
    walls = (wall('funnel_a', (0.3, 0.1), (0.6, gap / 2)),
             wall('funnel_b', (0.3, -0.1), (0.6, -gap / 2)))
    pt = disc(restitution=0.3, mu_s=0.5, mu_k=0.4)
    sim = MicroSim(make_cell(part_types=(pt,), obstacles=walls, speed=speed), seed=0)
    for row in range(8):
        for k in range(12):
            sim.spawn(0, 0.1 + row * (D + 3e-3), (k - 5.5) * (D + 3e-3), 0.0, vx=speed)
    return sim


def cone_violation(sim):
    """Return the largest ``|lt| - mu ln`` of the last substep's contacts and whether a contact
    without normal impulse holds a tangential one."""
    nc = int(sim._prev[-1, 0])
    ct = sim._ct[:nc]
    mu = np.maximum(ct[:, CT_MU_S], ct[:, CT_MU_K])
    excess = float((abs(ct[:, CT_LT]) - mu * ct[:, CT_LN]).max(initial=-1.0))
    return excess, bool(np.any((ct[:, CT_LN] == 0.0) & (ct[:, CT_LT] != 0.0)))


@pytest.mark.parametrize('scene', ['pile', 'arch'])
def test_friction_stays_inside_the_coulomb_cone(scene):
    sim = queue_pile(0.5) if scene == 'pile' else funnel(2.5 * D)
    carried = 0
    for _ in range(1500):
        sim.step(1)
        excess, loose = cone_violation(sim)
        assert excess <= 1e-12 and not loose
        carried += int(np.count_nonzero(sim._ct[:int(sim._prev[-1, 0]), CT_LT]))
    assert carried > 1000      # friction was at work


# touching: 0.1 um apart (the spawn check refuses an overlap of round-off); 0.05-0.3 mm: the
# struck discs meet their neighbours within the substep, some contacts bouncing from their
# approach before it, others struck inside it; 0.5 mm: below a disc's travel in a step, so
# several contacts are solved in the same substep
@pytest.mark.parametrize('gap, reach', [(1e-7, 0.65), (5e-5, 0.65), (1e-4, 0.65), (2e-4, 0.65),
                                        (3e-4, 0.7), (5e-4, 0.7)])
def test_billiard_break_keeps_its_kinetic_energy(gap, reach):
    # elastic, frictionless: the hard-disc answer loses nothing
    sim = billiard(gap)
    e0 = kinetic_energy(sim)
    sim.step(300)
    assert kinetic_energy(sim) >= 0.98 * e0
    v = sim.parts_view()
    assert abs(v.vx.sum() - 1.0) <= 1e-9 and abs(v.vy.sum()) <= 1e-9     # momentum kept
    assert v.x.max() > reach      # the break moved the back row (it starts at 0.635-0.637 m)


def test_elastic_gas_keeps_its_kinetic_energy():
    sim = gas(0.25)
    e0 = kinetic_energy(sim)
    sim.step(1000)
    assert kinetic_energy(sim) >= 0.95 * e0


def test_pile_arriving_at_2_m_s_overlaps_less_than_5_percent():
    sim = queue_pile(2.0)
    worst = 0.0
    for _ in range(600):
        sim.step(1)
        worst = max(worst, deepest_overlap(sim))
    assert sim.parts_view().x.max() > 0.9     # the pile reached the queue
    assert worst <= 0.05 * D


def test_parts_hit_by_a_pusher_at_its_maximum_speed_overlap_less_than_5_percent():
    pusher = Actuator(name='pusher', kind='pusher', base=(0.5, 0.2), axis=(0.0, -1.0),
                      length=0.02, width=0.15, position_range=(0.0, 0.3), max_speed=0.8,
                      initial_position=0.0)
    pt = disc(restitution=0.3, mu_s=0.3, mu_k=0.2)
    sim = MicroSim(make_cell(part_types=(pt,), actuators=(pusher,)), seed=0)
    for row in range(4):
        for k in range(6):
            sim.spawn(0, 0.47 + k * (D + 1e-4), 0.12 - row * (D + 1e-4), 0.0)
    sim.set_actuator_target(0, 0.3)
    worst = 0.0
    for _ in range(500):
        sim.step(1)
        worst = max(worst, deepest_overlap(sim))
    assert sim.parts_view().y.min() < -0.1      # pushed across
    assert worst <= 0.05 * D


def test_speculative_contact_stops_a_fast_disc_at_a_wall_without_overlap():
    cell = make_cell(part_types=(disc(restitution=0.0),), friction=0.0,
                     obstacles=(wall('w', (0.8, -0.1), (0.8, 0.1), restitution=0.0),))
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.5, 0.0, 0.0, vx=2.0)
    worst = 0.0
    for _ in range(300):
        sim.step(1)
        worst = max(worst, deepest_overlap(sim))
    v = sim.parts_view()
    assert v.x[0] == pytest.approx(0.8 - R, abs=1e-9)
    assert v.vx[0] == pytest.approx(0.0, abs=1e-12)
    assert worst <= 1e-12


def test_sweeps_are_deterministic():
    def run():
        sim = funnel(2.0 * D)
        sim.step(800)
        return sim.state_bytes()
    assert run() == run()
