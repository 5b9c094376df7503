"""Curved belts and transfer units on the macro grid: conservation, transit time, switching."""

import math

import numpy as np
import pytest

from conveyor_twin.cell.model import Actuator
from conveyor_twin.macro import MacroSim
from .cells import belt, curved_belt, make_cell, rails_of, RHO_MAX, wall

COMBOS = [(v, s) for v in ('capped', 'goettlich') for s in ('upwind', 'limited')]
U = 0.5  # m/s


def _ring_cell(variant, scheme):
    """A full-turn curve (radii 0.2-0.3 m, guide rails) blocked by a radial wall at 90 deg."""
    ring = curved_belt('ring', (0.0, 0.0), 0.2, 0.3, 0.0, 360.0, U, guide_rails=True)
    block = wall('block', (0.0, 0.19), (0.0, 0.31))
    return make_cell(region=(-0.32, -0.32, 0.32, 0.32), belts=[ring],
                     obstacles=(block,) + rails_of(ring), variant=variant, scheme=scheme)


@pytest.mark.parametrize('variant,scheme', COMBOS)
def test_mass_conserved_on_a_closed_curve_and_the_queue_respects_rho_max(variant, scheme):
    sim = MacroSim(_ring_cell(variant, scheme))
    on_belt = sim._belt_idx >= 0
    fluid = on_belt & (sim.solid == 0)
    sim.density[fluid] = 0.5 * RHO_MAX
    initial = sim.total_parts()
    assert initial > 300.0
    for _ in range(4):
        sim.step(2500)
        assert abs(sim.total_parts() - initial) <= 1e-12 * initial
    assert sim.parts_out == 0.0 and sim.parts_in == 0.0
    assert sim.density.min() >= 0.0
    assert sim.density.max() <= RHO_MAX * (1.0 + 1e-12)
    # Nothing left the curve sideways: off the belt there is no density.
    assert float(sim.density[~on_belt].sum()) == 0.0
    # A queue packed against the wall: upstream of it (the rotation is counter-clockwise)
    # about half the belt is full, the quarter just downstream of it ran empty.
    xs, ys = sim.grid.centres()
    packed = np.count_nonzero(sim.density[fluid] > 0.99 * RHO_MAX)
    assert 0.4 * fluid.sum() < packed < 0.55 * fluid.sum()
    downstream = fluid & (xs < 0.0) & (ys > 0.0)
    assert float(sim.density[downstream].sum()) * sim.resolution ** 2 < 1e-6 * initial


def _l_line(scheme):
    """Straight in (along +x), a 90 deg counter-clockwise curve (centre line radius 0.4 m),
    straight out (along +y); all 0.2 m wide, at U."""
    belts = [belt((-0.4, -0.4), (0.0, -0.4), 0.2, U),
             curved_belt('curve', (0.0, 0.0), 0.3, 0.5, -90.0, 0.0, U),
             belt((0.4, 0.0), (0.4, 0.4), 0.2, U)]
    return make_cell(region=(-0.4, -0.5, 0.5, 0.4), belts=belts, scheme=scheme)


@pytest.mark.parametrize('scheme', ['upwind', 'limited'])
def test_a_pulse_crosses_a_90_degree_curve_in_the_time_of_its_centre_line(scheme):
    """A pulse deposited on the in-belt leaves through the end of the out-belt; the mean
    arrival time of the outflow is the centre-line path over the speed.

    For linear advection with a numerical diffusion the flux-weighted mean arrival time at a
    line is the advection time (the diffusion spreads the arrivals about it without moving
    their mean); on the curve every radius turns at the same angular speed ``U / R_c``, so
    every part of the pulse takes the centre line's time there. What is left is the grid's
    rims: a cell holding a sliver of the annulus has the whole cell's volume but only the
    sliver's flux, so what the numerical diffusion spreads into it leaves late, as a thin
    exponential tail. Measured: upwind (diffusion ``U h (1 - c) / 2``) 0.9 % late with 1e-4 of
    the pulse still on the rims after 6 s; limited (second order, hardly any diffusion)
    0.01 %. The bound is 1.5 %, 40 ms on 2.66 s (two cell transits ``h / U``).
    """
    sim = MacroSim(_l_line(scheme))
    sim.deposit(-0.3, -0.4, 0.03, 10.0)
    path = 0.3 + 0.4 * 0.5 * math.pi + 0.4      # m: in-belt, curve centre line, out-belt
    expected = path / U
    top = slice(2 * sim.ny + sim.nx, 2 * (sim.nx + sim.ny))   # the top boundary faces
    times, amounts = [], []
    for k in range(1, 6001):
        sim.step(1)
        out = float(sim.outflow[top].sum())
        if out:
            times.append(k * sim.dt)
            amounts.append(out)
    amounts = np.array(amounts)
    # all of it came out at the top, but for the rims' tail
    assert amounts.sum() == pytest.approx(10.0, abs=2e-3)
    assert sim.total_parts() + amounts.sum() == pytest.approx(10.0, rel=1e-12)
    mean_arrival = float(np.dot(times, amounts) / amounts.sum())
    assert mean_arrival == pytest.approx(expected, rel=0.015)


def _transfer(position):
    return Actuator('xfer', 'transfer', (0.5, 0.0), (0.0, 1.0), 0.2, 0.1, (0.0, 0.01), 0.1,
                    position, engage_height=0.005, friction=0.5, surface_speed=0.3)


def test_a_transfer_units_field_switches_with_its_state():
    """Lowered, the belt carries the cells over the transfer unit (across the whole belt)
    along x; lifted, they move across at its surface speed; it is never solid; lowered again,
    the belt field is back."""
    cell = make_cell(region=(0.0, -0.1, 1.0, 0.1), belts=[belt((0.0, 0.0), (1.0, 0.0), 0.2, U)],
                     actuators=[_transfer(0.0)])
    sim = MacroSim(cell)
    xs, ys = sim.grid.centres()
    under = np.abs(xs - 0.5) < 0.05              # across the whole belt
    assert under.sum() == 200
    belt_field = sim.cell_velocity.copy()
    faces = tuple(f.copy() for f in sim.face_velocity)
    assert np.all(belt_field[under] == [U, 0.0])
    sim.set_actuator_positions([0.004])          # rising, below engage_height
    assert np.array_equal(sim.cell_velocity, belt_field)
    sim.set_actuator_positions([0.01])           # lifted
    assert np.all(sim.cell_velocity[under] == [0.0, 0.3])
    assert np.array_equal(sim.cell_velocity[~under], belt_field[~under])
    assert not sim.solid.any()
    # Material on the unit leaves sideways (through the top boundary), none along the belt.
    sim.deposit(0.5, 0.0, 0.02, 2.0)
    sim.step(2000)
    right = slice(sim.ny, 2 * sim.ny)
    top = slice(2 * sim.ny + sim.nx, 2 * (sim.nx + sim.ny))
    assert float(sim.outflow_total[top].sum()) == pytest.approx(2.0, rel=1e-9)
    assert float(sim.outflow_total[right].sum()) == 0.0
    sim.set_actuator_positions([0.0])
    assert np.array_equal(sim.cell_velocity, belt_field)
    for before, after in zip(faces, sim.face_velocity):
        assert np.array_equal(before, after)
