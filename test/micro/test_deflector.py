"""A part sliding along a deflector, and a jam at the deflector."""

import numpy as np
import pytest

from conveyor_twin.bench import micro as bench
from conveyor_twin.micro import MicroSim
from test.micro.conftest import disc, make_cell, wall

V = 0.5
MU_D = 0.15
HALF = 0.005


def test_slides_along_deflector_and_leaves_at_its_end():
    # 45 degree deflector from (1.0, 0.2) to (1.3, -0.1); the disc arrives on the belt
    a, b = np.array([1.0, 0.2]), np.array([1.3, -0.1])
    deflector = wall('deflector', tuple(a), tuple(b), thickness=2 * HALF, restitution=0.2,
                     friction=MU_D, kind='deflector')
    r = 0.005
    cell = make_cell(part_types=(disc(restitution=0.4, mu_s=0.25, mu_k=0.18),),
                     obstacles=(deflector,), speed=V, friction=0.35)
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.8, 0.1, 0.0, vx=V)
    d = (b - a) / np.linalg.norm(b - a)
    n = np.array([-d[1], d[0]])                       # normal to the upstream side
    n = -n if n @ np.array([-1.0, 0.0]) < 0 else n
    length = np.linalg.norm(b - a)
    sliding = []
    last_contact = None
    for _ in range(3000):
        sim.step(1)
        p = np.array([sim.parts_view().x[0], sim.parts_view().y[0]])
        v = np.array([sim.parts_view().vx[0], sim.parts_view().vy[0]])
        s = (p - a) @ d
        dist = (p - a) @ n
        if dist < r + HALF + 2e-4 and 0.0 < s < length:
            last_contact = (s, dist)
            if 0.3 * length < s < 0.9 * length:
                sliding.append((v @ d, dist, v @ n))
    sliding = np.array(sliding)
    assert len(sliding) > 100
    # centre rides at r + thickness/2 from the deflector line (within the slop)
    assert np.all(np.abs(sliding[:, 1] - (r + HALF)) < 2e-4)
    # steady sliding speed: belt friction along d balances the deflector's Coulomb friction
    # (V.d - u) = mu_d (-V.n)  ->  u = V.d - mu_d |V.n|
    expected = V * d[0] - MU_D * abs(V * n[0])
    assert np.median(sliding[-50:, 0]) == pytest.approx(expected, rel=0.02)
    # it leaves at the downstream end (past the end of the straight part) and then runs free
    assert last_contact[0] > length - 0.01
    p = np.array([sim.parts_view().x[0], sim.parts_view().y[0]])
    assert p[0] > b[0] and p[1] < b[1] - r


def test_jam_at_deflector_stays_bounded():
    sim = bench.jammed_sim(300, 1500)
    r = sim.cell.part_types[0].radius
    assert bench.max_penetration(sim) < 0.1 * r           # < 0.5 mm after 1.5 s of jam
    sim.step(500)
    assert bench.max_penetration(sim) < 0.1 * r
    v = sim.parts_view()
    assert np.all(np.abs(v.y) < 0.25) and np.all(v.x + v.y < 1.5)
    assert sim.counters()['contacts_full'] == 0
