"""Transfer units: lifted to their engage height, their rollers carry parts along their axis."""

import math

import pytest

from conveyor_twin.cell.loader import load_cell_text
from conveyor_twin.micro import MicroSim

G = 9.81
STROKE = 0.02          # m
ENGAGE = 0.01          # m
TRAVEL_TIME = 0.2      # s for the whole lift
SURFACE_SPEED = 0.5    # m/s along +y
ROLLER_MU = 0.6


def transfer_cell(belt_speed):
    """A belt along +x (y in [-0.3, 0.3]) with a transfer unit carrying along +y at x = 1."""
    return load_cell_text(f'''
cell: {{name: transfer, step: 0.001, seed: 1}}
micro: {{capacity: 16}}
belts:
  - {{name: main, start: [0.0, 0.0], end: [3.0, 0.0], width: 0.6, speed: {belt_speed},
     max_speed: 2.0, acceleration: 1.0, friction: 0.35}}
part_types:
  - {{name: can, shape: disc, radius: 0.02, height: 0.05, mass: 0.1}}
actuators:
  - {{name: xfer, kind: transfer, base: [1.0, 0.0], axis: [0.0, 1.0], length: 0.6, width: 0.3,
     stroke: {STROKE}, engage_height: {ENGAGE}, travel_time: {TRAVEL_TIME},
     surface_speed: {SURFACE_SPEED}, friction: {ROLLER_MU}, initial_position: 0.0}}
''')


def test_lowered_it_leaves_the_parts_to_the_belt():
    cell = transfer_cell(0.5)
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.8, -0.1, 0.0, vx=0.5)
    for _ in range(300):                                # 0.3 s: right across the footprint
        sim.step(1)
        p = sim.parts_view()
        assert (p.vx[0], p.vy[0], p.y[0]) == (0.5, 0.0, -0.1)
    assert p.x[0] == pytest.approx(0.95, abs=1e-9)


def test_lifted_it_carries_sideways_after_its_travel_time():
    cell = transfer_cell(0.0)                           # the belt stands still
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 1.0, -0.25, 0.0)
    sim.set_actuator_target(0, STROKE)
    dt = cell.settings.step
    engaged_at = carried_at = at_speed = None
    for k in range(1, 400):
        sim.step(1)
        p = sim.parts_view()
        assert p.vx[0] == 0.0 and p.wz[0] == 0.0
        if engaged_at is None and sim.actuator_position[0] >= ENGAGE:
            engaged_at = k
        if carried_at is None and p.vy[0] > 0.0:
            carried_at = k
            assert p.vy[0] == pytest.approx(ROLLER_MU * G * dt, rel=1e-9)
        if at_speed is None and p.vy[0] == SURFACE_SPEED:
            at_speed = k
        if sim.actuator_position[0] == STROKE and at_speed is not None:
            break
    # lifted at stroke / travel_time: it carries from the step its lift reaches engage_height
    assert carried_at == engaged_at
    assert engaged_at * dt == pytest.approx(TRAVEL_TIME * ENGAGE / STROKE, abs=1.5 * dt)
    assert k * dt == pytest.approx(TRAVEL_TIME, abs=1.5 * dt)
    assert at_speed * dt == pytest.approx(TRAVEL_TIME * ENGAGE / STROKE
                                   + SURFACE_SPEED / (ROLLER_MU * G), abs=2.5 * dt)
    # lowered again, the still belt stops the part
    sim.set_actuator_target(0, 0.0)
    released_at = None
    for j in range(1, 200):
        sim.step(1)
        p = sim.parts_view()
        if released_at is None and p.vy[0] < SURFACE_SPEED:
            released_at = j
            assert sim.actuator_position[0] < ENGAGE
            assert p.vy[0] == pytest.approx(SURFACE_SPEED - 0.35 * G * dt, rel=1e-9)
    assert released_at * dt == pytest.approx(TRAVEL_TIME * (STROKE - ENGAGE) / STROKE,
                                           abs=1.5 * dt)


def test_it_turns_a_moving_part_onto_its_axis():
    cell = transfer_cell(0.5)
    sim = MicroSim(cell, seed=0)
    sim.set_actuator_target(0, STROKE)
    sim.step(int(round(TRAVEL_TIME / cell.settings.step)))
    assert sim.actuator_position[0] == pytest.approx(STROKE)
    sim.spawn(0, 0.84, -0.25, 0.0, vx=0.5)              # enters the lifted footprint
    while sim.parts_view().vy[0] < SURFACE_SPEED:
        sim.step(1)
        p = sim.parts_view()
        # the slip relaxes along a straight line: both components reach the rollers' together
        assert p.vx[0] == pytest.approx(0.5 * (1.0 - p.vy[0] / SURFACE_SPEED), abs=1e-12)
    p = sim.parts_view()
    assert (p.vx[0], p.vy[0]) == (0.0, SURFACE_SPEED)
    assert abs(p.x[0] - 1.0) <= 0.15                    # still over the footprint
    assert math.hypot(p.vx[0], p.vy[0]) == SURFACE_SPEED
