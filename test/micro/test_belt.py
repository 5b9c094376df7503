"""Belt drive: a part dropped on a running belt reaches its speed after dv / (mu g)."""

import math

import numpy as np
import pytest

from conveyor_twin.micro import MicroSim
from conveyor_twin.micro.contacts.tables import MP_DT
from conveyor_twin.micro.drive import belt_drive
from conveyor_twin.micro.state import P_VX, P_VY, P_WZ, P_X, P_Y
from test.micro.conftest import make_cell

G = 9.81


@pytest.mark.parametrize('mu, speed', [(0.35, 0.5), (0.2, 1.0)])
def test_reaches_belt_speed_after_dv_over_mu_g(mu, speed):
    cell = make_cell(speed=speed, friction=mu)
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.2, 0.0, 0.0)                       # dropped at rest
    dt = cell.settings.step
    expected = speed / (mu * G)                        # [s]
    steps = 0
    while sim.parts_view().vx[0] < speed:
        sim.step(1)
        steps += 1
        # constant acceleration mu g until then
        if sim.parts_view().vx[0] < speed:
            assert sim.parts_view().vx[0] == pytest.approx(mu * G * steps * dt, rel=1e-9)
    assert steps == math.ceil(expected / dt - 1e-9)
    assert sim.parts_view().vy[0] == 0.0


def test_spin_stops_under_belt_torque():
    # uniform pressure: torque mu m g (2 R / 3), so w0 stops after w0 I / (mu m g 2R/3)
    cell = make_cell(speed=0.0, friction=0.3)
    part = cell.part_types[0]
    sim = MicroSim(cell, seed=0)
    w0 = 20.0
    sim.spawn(0, 0.2, 0.0, 0.0, wz=w0)
    expected = w0 * part.inertia / (0.3 * part.mass * G * 2 * part.radius / 3)
    steps = 0
    while sim.parts_view().wz[0] != 0.0:
        sim.step(1)
        steps += 1
    assert steps * cell.settings.step == pytest.approx(expected, abs=cell.settings.step)


def test_belt_speed_ramps_with_acceleration_limit():
    cell = make_cell(speed=0.0)
    sim = MicroSim(cell, seed=0)
    sim.set_belt_target(0, 1.0)
    sim.step(100)                                       # 0.1 s at 2 m/s^2
    assert sim.belt_speed[0] == pytest.approx(0.2, abs=1e-12)
    sim.step(400)
    assert sim.belt_speed[0] == 1.0 and sim.belt_target[0] == 1.0


def test_surface_friction_heat_is_the_work_less_the_kinetic_energy_gained():
    # belt_drive's heat, per part: J . u - (change of kinetic energy) for the friction impulse
    # J and the surface velocity u: what friction turns into heat, >= 0, also for spin
    cell = make_cell(speed=0.5, friction=0.3)
    sim = MicroSim(cell, seed=0)
    rng = np.random.default_rng(1)
    n = 6
    sim.spawn(0, np.linspace(0.05, 0.4, n), 0.0, 0.0, vx=rng.normal(0.5, 0.01, n),
              vy=rng.normal(0.0, 0.01, n), wz=rng.normal(0.0, 5.0, n))
    part = cell.part_types[0]
    P = sim.state.P
    v0 = P[[P_VX, P_VY, P_WZ], :n].copy()
    heat = np.full(n, np.nan)
    sim.mp[MP_DT] = cell.settings.step
    belt_drive(n, sim.state.part_type, P[P_X], P[P_Y], P[P_VX], P[P_VY], P[P_WZ], sim.pt,
               sim.surfaces, np.array([0.5]), sim.mp, sim.acc, heat)
    v1 = P[[P_VX, P_VY, P_WZ], :n]
    j = part.mass * (v1[:2] - v0[:2])
    work = j[0] * 0.5                                   # the surface moves along +x at 0.5
    gained = (0.5 * part.mass * ((v1[:2] ** 2).sum(0) - (v0[:2] ** 2).sum(0))
              + 0.5 * part.inertia * (v1[2] ** 2 - v0[2] ** 2))
    assert np.all(heat >= 0.0)
    assert heat == pytest.approx(work - gained, rel=1e-9, abs=1e-15)
