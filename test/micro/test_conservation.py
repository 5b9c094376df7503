"""Dense contact without external work: momentum kept, kinetic energy never rising; a pile held.

No gravity means no belt or floor friction (both are bounded by mu m g), so the contacts are the
only forces: total linear and angular momentum must stay, and the kinetic energy may only fall.
"""

from dataclasses import replace

import numpy as np
import pytest

from conveyor_twin.micro import MicroSim
from test.micro.conftest import box, disc, make_cell, wall

R = 0.005
M = 0.01


def hex_lattice(centre, count, spacing, rng=None, jitter=0.0):
    """Return ``count`` points of a hexagonal lattice around ``centre``, nearest first."""
    k = int(np.sqrt(count)) + 4
    i, j = np.meshgrid(np.arange(-k, k + 1), np.arange(-k, k + 1))
    x = (i + 0.5 * (j % 2)).ravel() * spacing
    y = j.ravel() * spacing * np.sqrt(3.0) / 2.0
    order = np.argsort(np.hypot(x, y), kind='stable')[:count]
    pts = np.stack([x[order], y[order]], 1) + centre
    if rng is not None:
        pts += rng.uniform(-jitter, jitter, pts.shape)
    return pts


def weightless(cell):
    """Return ``cell`` without gravity (no belt or floor friction)."""
    return replace(cell, settings=replace(cell.settings, gravity=0.0))


def momenta(sim, m, inertia):
    """Return (P_x, P_y, L_z about the origin) of the parts and the scale of each."""
    v = sim.parts_view()
    px, py = m * v.vx, m * v.vy
    lz = v.x * py - v.y * px + inertia * v.wz
    scale_p = float(np.sum(m * np.hypot(v.vx, v.vy)))
    scale_l = float(np.sum(np.hypot(v.x, v.y) * m * np.hypot(v.vx, v.vy) + inertia * abs(v.wz)))
    return np.array([px.sum(), py.sum(), lz.sum()]), scale_p, scale_l


def kinetic(sim, m, inertia):
    v = sim.parts_view()
    return 0.5 * float(np.sum(m * (v.vx ** 2 + v.vy ** 2) + inertia * v.wz ** 2))


def free_cluster(slop):
    """Return a simulator of 200 touching discs with random velocities, no walls, no gravity."""
    part = disc(radius=R, mass=M, restitution=0.5, mu_s=0.4, mu_k=0.3)
    cell = weightless(make_cell(part_types=(part,), length=2.0, width=1.0,
                                penetration_slop=slop))
    sim = MicroSim(cell, seed=0)
    rng = np.random.default_rng(7)
    pts = hex_lattice((1.0, 0.0), 200, 2 * R * (1 + 1e-6))
    v = rng.normal(scale=0.1, size=pts.shape)
    w = rng.normal(scale=5.0, size=len(pts))
    ids = sim.spawn(0, pts[:, 0], pts[:, 1], 0.0, vx=v[:, 0], vy=v[:, 1], wz=w)
    assert np.all(ids > 0)
    return sim, part


def test_free_cluster_keeps_linear_and_angular_momentum():
    # the penetration correction moves positions, not velocities: linear momentum stays with
    # it; without it (slop larger than any overlap) the angular momentum about a fixed point
    # stays as well, which the correction would change by m dx x v
    sim, part = free_cluster(slop=1.0)
    inertia = part.inertia
    p0, scale_p, scale_l = momenta(sim, M, inertia)
    worst = np.zeros(3)
    for _ in range(2000):
        sim.step(1)
        p, _, _ = momenta(sim, M, inertia)
        worst = np.maximum(worst, abs(p - p0))
    assert sim.n == 200
    assert worst[0] <= 1e-12 * scale_p and worst[1] <= 1e-12 * scale_p
    assert worst[2] <= 1e-12 * scale_l


def test_free_cluster_keeps_linear_momentum_with_position_correction():
    sim, part = free_cluster(slop=1e-4)
    p0, scale_p, _ = momenta(sim, M, part.inertia)
    centre0 = np.mean(np.stack([sim.parts_view().x, sim.parts_view().y]), axis=1)
    for _ in range(2000):
        sim.step(1)
        p, _, _ = momenta(sim, M, part.inertia)
        assert np.all(abs(p[:2] - p0[:2]) <= 1e-12 * scale_p)
    # the centre of mass moves with the constant momentum (the correction keeps it)
    v = sim.parts_view()
    centre = np.array([v.x.mean(), v.y.mean()])
    drift = centre - centre0 - p0[:2] / (M * sim.n) * sim.time
    assert np.all(abs(drift) < 1e-12)


def test_dense_walled_packing_never_gains_kinetic_energy():
    # 60 % area fraction in a closed box, random velocities and spins, no gravity
    part = disc(radius=R, mass=M, restitution=0.5, mu_s=0.4, mu_k=0.3)
    x0, x1, y0, y1 = 0.9, 1.1, -0.1, 0.1
    walls = (wall('s', (x0, y0), (x1, y0), restitution=0.5, friction=0.3),
             wall('e', (x1, y0), (x1, y1), restitution=0.5, friction=0.3),
             wall('n', (x1, y1), (x0, y1), restitution=0.5, friction=0.3),
             wall('w', (x0, y1), (x0, y0), restitution=0.5, friction=0.3))
    cell = weightless(make_cell(part_types=(part,), obstacles=walls, width=0.5, capacity=1024))
    sim = MicroSim(cell, seed=0)
    rng = np.random.default_rng(11)
    spacing = R * np.sqrt(2 * np.pi / (0.6 * np.sqrt(3.0)))     # 60 % area fraction
    pts = hex_lattice((1.0, 0.0), 600, spacing)
    inside = ((pts[:, 0] > x0 + R) & (pts[:, 0] < x1 - R)
              & (pts[:, 1] > y0 + R) & (pts[:, 1] < y1 - R))
    pts = pts[inside]
    assert len(pts) * np.pi * R * R / ((x1 - x0) * (y1 - y0)) > 0.5
    v = rng.normal(scale=0.3, size=pts.shape)
    ids = sim.spawn(0, pts[:, 0], pts[:, 1], 0.0, vx=v[:, 0], vy=v[:, 1],
                    wz=rng.normal(scale=10.0, size=len(pts)))
    assert np.all(ids > 0)
    k_prev = kinetic(sim, M, part.inertia)
    k_start = k_prev
    for _ in range(2000):
        sim.step(1)
        k = kinetic(sim, M, part.inertia)
        assert k <= k_prev * (1 + 1e-12) + 1e-300
        k_prev = k
    assert sim.n == len(pts)
    assert k_prev < 0.5 * k_start       # collisions dissipate


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_pile_of_boxes_against_a_wall_on_a_running_belt_stays_at_rest(seed):
    # a channel 0.1 m wide, closed by a wall across the belt; 40 boxes at random poses pressed
    # against it by the belt running under them at 0.3 m/s. Boxes: a disc in a pile may roll
    # along a neighbour or the wall (see docs/models.md, "Limits")
    walls = (wall('left', (0.0, 0.05), (0.6, 0.05), friction=0.3),
             wall('right', (0.0, -0.05), (0.6, -0.05), friction=0.3),
             wall('end', (0.5, -0.06), (0.5, 0.06), friction=0.3))
    cell = make_cell(part_types=(box(),), obstacles=walls, speed=0.3, width=0.2)
    sim = MicroSim(cell, seed=0)
    rng = np.random.default_rng(seed)
    placed = 0
    while placed < 40:
        ids = sim.spawn(0, rng.uniform(0.3, 0.49), rng.uniform(-0.04, 0.04),
                        rng.uniform(-np.pi, np.pi), vx=0.3, strict=False)
        placed += int(ids[0] != 0)
    sim.step(6000)            # settle
    v = sim.parts_view()
    start = np.stack([v.x.copy(), v.y.copy(), v.yaw.copy()])
    fastest = 0.0
    for _ in range(10):
        sim.step(100)
        v = sim.parts_view()
        fastest = max(fastest, float(np.max(np.hypot(v.vx, v.vy))),
                      float(np.max(np.abs(v.wz))) * 0.01)     # spin at the boxes' corners
    moved = np.max(np.abs(np.stack([v.x, v.y, v.yaw]) - start))
    assert sim.n == 40
    # at rest against the wall while the belt runs at 0.3 m/s under it
    assert fastest < 1e-9
    assert moved < 1e-9
    assert np.all(v.x < 0.5)
