"""Curved belts: a rigid rotation of the surface about the curve's centre."""

import math

import numpy as np
import pytest

from conveyor_twin.cell.loader import load_cell_text
from conveyor_twin.micro import MicroSim
from conveyor_twin.micro.drive import surface_velocity
from conveyor_twin.micro.footprint import footprint_table
from conveyor_twin.micro.surfaces import belt_table, transfer_table

G = 9.81


def curve_cell(*, speed=0.5, friction=0.5, rails=False, straight=False, sweep=270.0,
               radius=0.02, source=''):
    """A curve about (0, 0), radii 0.3 .. 0.7 m, from -90 deg counter-clockwise by ``sweep``;
    ``straight``: with an infeed along +x ending at the curve's start (y in [-0.7, -0.3])."""
    infeed = f'''
  - {{name: infeed, start: [-2.0, -0.5], end: [0.0, -0.5], width: 0.4, speed: {speed},
     max_speed: 2.0, acceleration: 1.0, friction: {friction}}}''' if straight else ''
    text = f'''
cell: {{name: curve, step: 0.001, seed: 1}}
micro: {{capacity: 64}}
belts:{infeed}
  - name: bend
    curve: {{centre: [0.0, 0.0], inner_radius: 0.3, outer_radius: 0.7, start_angle: -90,
            end_angle: {-90.0 + sweep}, direction: ccw, guide_rails: {str(rails).lower()}}}
    speed: {speed}
    max_speed: 2.0
    acceleration: 1.0
    friction: {friction}
part_types:
  - {{name: can, shape: disc, radius: {radius}, height: 0.05, mass: 0.1}}
{source}'''
    return load_cell_text(text)


def spawn_on_curve(sim, radius, angle, omega, yaw=0.3):
    """Spawn a part at ``radius`` [m], polar ``angle`` [rad], moving with the surface."""
    x, y = radius * math.cos(angle), radius * math.sin(angle)
    sim.spawn(0, x, y, yaw, vx=-omega * y, vy=omega * x, wz=omega)


def wrap(a):
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@pytest.mark.parametrize('radius', [0.35, 0.5, 0.65])
def test_a_sticking_part_corotates_on_its_arc(radius):
    speed = 0.5
    cell = curve_cell(speed=speed, friction=0.5)
    omega = speed / 0.5                                 # rad/s, about the centre line
    assert radius * omega ** 2 < 0.5 * G                # friction holds it
    sim = MicroSim(cell, seed=0)
    a0 = -0.45 * math.pi
    spawn_on_curve(sim, radius, a0, omega)
    dt = cell.settings.step
    worst = 0.0
    for k in range(1, 3001):                            # 3 s, 3 rad: still on the curve
        sim.step(1)
        p = sim.parts_view()
        t = k * dt
        travelled = radius * omega * t                  # [m]
        angle = a0 + omega * t
        off_arc = abs(math.hypot(p.x[0], p.y[0]) - radius)
        off_point = math.hypot(p.x[0] - radius * math.cos(angle),
                               p.y[0] - radius * math.sin(angle))
        worst = max(worst, off_arc / travelled, off_point / travelled)
        assert abs(wrap(p.yaw[0] - (0.3 + omega * t))) < 1e-9
        assert p.wz[0] == omega
    assert worst < 1e-6, worst
    # its speed is omega r: faster outside
    p = sim.parts_view()
    assert math.hypot(p.vx[0], p.vy[0]) == pytest.approx(omega * radius, rel=1e-6)


def test_too_little_friction_slides_out_to_the_guide_rail():
    speed, mu, part_radius = 1.5, 0.2, 0.02
    cell = curve_cell(speed=speed, friction=mu, rails=True, radius=part_radius)
    omega = speed / 0.5
    assert mu < speed ** 2 / (0.5 * G)                  # too fast for the centre line
    sim = MicroSim(cell, seed=0)
    spawn_on_curve(sim, 0.5, -0.5 * math.pi + 0.05, omega)
    radii, radial = [], []
    for _ in range(80):                                 # 1.6 s: to 165 deg, still on the curve
        sim.step(20)
        p = sim.parts_view()
        r = math.hypot(p.x[0], p.y[0])
        radii.append(r)
        radial.append((p.x[0] * p.vx[0] + p.y[0] * p.vy[0]) / r)
        assert r <= 0.7 - part_radius + 1e-3            # never through the rail
    # outward, until it meets the rail (and bounces)
    hit = next(k for k, r in enumerate(radii) if r > 0.7 - part_radius - 0.01)
    assert np.all(np.diff(radii[:hit + 1]) > 0.0)
    assert radii[hit] > radii[0] + 0.15
    # then it stays against the outer rail (whose chords vary the radius by 0.1 mm), carried
    # along it at about the surface's speed there
    settled = np.array(radii[-30:])
    assert np.all(np.abs(settled - (0.7 - part_radius)) < 3e-4)
    assert abs(np.mean(radial[-30:])) < 0.01
    p = sim.parts_view()
    along = (p.x[0] * p.vy[0] - p.y[0] * p.vx[0]) / radii[-1]
    assert along == pytest.approx(omega * radii[-1], rel=0.05)


def test_the_outside_is_faster_and_a_queue_compresses_inside():
    # two lanes of parts, spaced s on the straight infeed, enter the curve: each keeps the
    # curve's angular speed, so the spacing becomes s r / r_centre (inside shorter)
    speed, spacing = 0.5, 0.1
    lanes = (0.38, 0.62)                                # radii of the lanes on the curve [m]
    cell = curve_cell(speed=speed, friction=0.6, straight=True, sweep=90.0)
    sim = MicroSim(cell, seed=0)
    for r in lanes:
        for j in range(4):
            sim.spawn(0, -0.5 - j * spacing, -r, 0.0, vx=speed)
    sim.step(2000)                                      # all four of each lane on the curve
    p = sim.parts_view()
    omega = speed / 0.5
    for lane, r in enumerate(lanes):
        xs, ys = p.x[4 * lane:4 * lane + 4], p.y[4 * lane:4 * lane + 4]
        assert np.all(xs > 0.0) and np.all(ys < 0.0)    # on the curve (its fourth quadrant)
        assert np.hypot(xs, ys) == pytest.approx(r, abs=2e-3)
        arc = np.diff(np.arctan2(ys, xs)) * r           # spacing along the arc [m]
        assert -arc == pytest.approx(spacing * r / 0.5, rel=0.01)
        v = np.hypot(p.vx[4 * lane:4 * lane + 4], p.vy[4 * lane:4 * lane + 4])
        assert v == pytest.approx(omega * np.hypot(xs, ys), rel=1e-6)


def test_lookup_on_a_curve_and_its_edges():
    cell = curve_cell(sweep=90.0)
    surfaces = (belt_table(cell.belts, 0.001), transfer_table(()), np.zeros(0),
                footprint_table(3))
    speed = np.array([0.5])
    omega = 0.5 / 0.5
    for x, y, inside in [(0.0, -0.5, True), (0.5, 0.0, True), (0.35, -0.35, True),
                         (0.0, -0.29, False), (0.0, -0.71, False), (-0.01, -0.5, False),
                         (0.5, 0.01, False), (-0.5, 0.0, False)]:
        vx, vy, spin, mu = surface_velocity(surfaces, speed, x, y, 0.3)
        assert (mu == 0.5) == inside, (x, y)   # the curve's coefficient, else the floor's
        if inside:
            assert (vx, vy, spin, mu) == pytest.approx((-omega * y, omega * x, omega, 0.5))
            assert (vx, vy) == pytest.approx(cell.belts[0].surface_velocity((x, y), 0.5))
        else:
            assert (vx, vy, spin, mu) == (0.0, 0.0, 0.0, 0.3)


def test_sources_on_a_curve_give_the_surface_velocity():
    source = '''sources:
  - {name: feed, part_type: can, region: [0.3, 0.1, 0.6, 0.3], rate: 20.0, pattern: uniform,
     max_parts: 3}'''
    cell = curve_cell(speed=0.4, sweep=180.0, source=source)
    sim = MicroSim(cell, seed=2)
    sim.step(1)
    p = sim.parts_view()
    assert len(p) == 1
    # released at the step's start with the surface's velocity and spin, then one substep
    omega = 0.4 / 0.5
    assert p.wz[0] == omega
    assert (p.vx[0], p.vy[0]) == pytest.approx((-omega * p.y[0], omega * p.x[0]), rel=1e-3)
