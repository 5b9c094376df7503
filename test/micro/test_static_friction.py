"""Static friction: a part held by friction stays at rest and slides once friction cannot hold.

A part on a belt that decelerates more gently than ``mu g`` keeps the belt's speed; a part the
belt presses against a wall inclined at ``theta`` from the belt's cross direction stays where it
is if ``tan(theta) <= mu_s`` (the belt's push ``F`` along the belt has the component
``F sin(theta)`` along the wall and ``F cos(theta)`` against it), and slides along it otherwise.
The part is a box lying flat against the wall: a disc would roll along it, as round parts do
along guide rails, since the belt slipping under it barely resists a spin.
"""

import math
from dataclasses import replace

import numpy as np
import pytest

from conveyor_twin.micro import MicroSim
from test.micro.conftest import box, make_cell, wall

G = 9.81


@pytest.mark.parametrize('deceleration, held', [(2.0, True), (5.0, False)])
def test_part_keeps_the_speed_of_a_belt_decelerating_below_mu_g(deceleration, held):
    mu = 0.35                                            # mu g = 3.43 m/s^2
    cell = make_cell(speed=0.5, friction=mu)
    cell = replace(cell, belts=(replace(cell.belts[0], acceleration=deceleration),))
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.2, 0.0, 0.0, vx=0.5)
    sim.set_belt_target(0, 0.0)
    slip = 0.0
    while sim.belt_speed[0] > 0.0:
        sim.step(1)
        slip = max(slip, abs(sim.parts_view().vx[0] - sim.belt_speed[0]))
    if held:
        assert slip == 0.0
    else:
        # the part decelerates at mu g while the belt decelerates faster
        assert slip > 0.1


def _against_inclined_wall(theta_deg: float, steps: int):
    """Return the positions [m] of a box the belt presses flat against a wall inclined at
    ``theta_deg``, after 0.2 s of settling and after ``steps`` more steps, and its speed."""
    theta = math.radians(theta_deg)
    part = box()                                         # with the wall's 0.3: mu_s 0.45
    c = (0.5, 0.0)
    d = (math.sin(theta), math.cos(theta))               # along the wall
    inclined = wall('inclined', (c[0] - 0.1 * d[0], c[1] - 0.1 * d[1]),
                    (c[0] + 0.1 * d[0], c[1] + 0.1 * d[1]), friction=0.3)
    cell = make_cell(part_types=(part,), obstacles=(inclined,), speed=0.3, friction=0.35)
    sim = MicroSim(cell, seed=0)
    n = (-math.cos(theta), math.sin(theta))              # wall normal toward the belt's start
    r = 0.5 * part.width * (1 + 1e-3)
    sim.spawn(0, c[0] + r * n[0], c[1] + r * n[1], math.atan2(d[1], d[0]))
    sim.step(200)
    v = sim.parts_view()
    start = np.array([v.x[0], v.y[0], v.yaw[0]])
    sim.step(steps)
    v = sim.parts_view()
    return start, np.array([v.x[0], v.y[0], v.yaw[0]]), np.hypot(v.vx[0], v.vy[0])


FRICTION_ANGLE = math.degrees(math.atan(0.45))          # 24.2 deg


@pytest.mark.parametrize('theta', [0.0, 10.0, FRICTION_ANGLE - 1.0])
def test_part_against_a_wall_inside_the_friction_angle_stays_at_rest(theta):
    start, end, speed = _against_inclined_wall(theta, 1000)
    assert np.max(np.abs(end - start)) < 1e-9
    assert speed < 1e-9


@pytest.mark.parametrize('theta', [FRICTION_ANGLE + 1.0, 32.0])
def test_part_against_a_wall_beyond_the_friction_angle_slides_along_it(theta):
    start, end, speed = _against_inclined_wall(theta, 1000)
    assert np.hypot(*(end[:2] - start[:2])) > 0.005
    assert speed > 0.005
