"""No tunnelling: fast discs against thin walls and pegs."""

import numpy as np
import pytest

from conveyor_twin.cell.model import Obstacle
from conveyor_twin.micro import MicroSim
from test.micro.conftest import disc, make_cell, wall


@pytest.mark.parametrize('speed', [2.0, 5.0, 12.0])
@pytest.mark.parametrize('angle', [0.0, 0.7])
def test_fast_disc_never_crosses_a_zero_thickness_wall(speed, angle):
    r = 0.005                                            # the default cell's smallest part
    cell = make_cell(part_types=(disc(radius=r, restitution=0.5),),
                     obstacles=(wall('w', (1.0, -0.25), (1.0, 0.25)),), friction=0.0)
    sim = MicroSim(cell, seed=0)
    ys = np.linspace(-0.2, 0.2, 9)
    sim.spawn(0, np.full(9, 0.9), ys, 0.0, vx=speed * np.cos(angle),
              vy=speed * np.sin(angle) * np.sign(-ys + 1e-9))
    travel = cell.micro.max_travel_fraction * r          # largest travel per substep
    for _ in range(200):
        sim.step(1)
        # penetration never exceeds one substep's travel: the centre stays on its side
        assert np.all(sim.parts_view().x <= 1.0 - r + travel + 1e-12)
    assert np.all(sim.parts_view().vx < 0.0)             # all bounced


def test_fast_disc_hits_a_peg():
    peg = Obstacle(name='peg', kind='peg', points=((1.0, 0.0),), radius=0.003)
    cell = make_cell(obstacles=(peg,), friction=0.0)
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.9, 0.001, 0.0, vx=2.0)
    for _ in range(150):
        sim.step(1)
        v = sim.parts_view()
        assert np.hypot(v.x[0] - 1.0, v.y[0]) > 0.008 - 0.0025
    assert sim.parts_view().vx[0] < 0.0
