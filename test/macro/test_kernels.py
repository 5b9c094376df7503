"""The kernels' work-skipping: y sweep on faces with y velocity only, cut chains, operator region.

The numba kernels skip faces that cannot change anything (zero y velocity, no receiver near
``rho_max``, no full cell near); these tests run scenes where the skipped and the worked parts
border each other (a deflector's sliding layer across a belt running along x, a pusher moving
across it) against the whole-grid NumPy reference, and check the invariant the y sweep relies
on (its work array is zero outside the faces it worked on).
"""

import numpy as np
import pytest

from conveyor_twin.cell.model import Actuator, Obstacle
from conveyor_twin.macro import MacroSim
from conveyor_twin.macro.reference import ReferenceSim
from .cells import belt, make_cell, RHO_MAX

COMBOS = [(v, s) for v in ('capped', 'goettlich') for s in ('upwind', 'limited')]


def _deflector_sim(variant, scheme, guard=True, mollifier_width=0.0):
    """A belt along x fed at 0.4 rho_max, a 45 degree deflector over 70 % of its width."""
    deflector = Obstacle('d', 'deflector', ((0.3, 0.1), (0.44, -0.04)), thickness=0.01)
    cell = make_cell(region=(0.0, -0.1, 0.6, 0.1), variant=variant, scheme=scheme,
                     belts=[belt((0.0, 0.0), (0.6, 0.0), 0.2, 0.5)], obstacles=[deflector],
                     mollifier_width=mollifier_width)
    sim = MacroSim(cell, guard=guard)
    rates = np.zeros(sim.grid.n_boundary)
    rates[:sim.ny] = 0.4 * RHO_MAX * 0.5 * sim.resolution
    sim.set_inflow(rates)
    return sim


@pytest.mark.parametrize('guard', [True, False])
@pytest.mark.parametrize('variant,scheme', COMBOS)
def test_deflector_jam_matches_numpy_reference(variant, scheme, guard):
    sim = _deflector_sim(variant, scheme, guard, mollifier_width=0.03)
    sim.step(1500)                                      # a queue in front of the deflector
    assert sim.density.max() >= RHO_MAX * (1.0 - 1e-9)
    assert np.count_nonzero(sim.face_velocity[1]) < 0.5 * sim.face_velocity[1].size
    ref = ReferenceSim(sim)
    sim.step(60)
    ref.step(60)
    assert np.abs(sim.density - ref.rho).max() <= 1e-11 * RHO_MAX
    assert np.abs(sim.outflow - ref.outflow).max() <= 1e-12 * max(1.0, sim.outflow.max())
    assert np.abs(sim.inflow - ref.inflow).max() <= 1e-12 * max(1.0, sim.inflow.max())


@pytest.mark.parametrize('variant,scheme', COMBOS)
def test_y_sweep_work_array_stays_zero_between_sweeps(variant, scheme):
    sim = _deflector_sim(variant, scheme)
    for _ in range(10):
        sim.step(100)
        assert not sim._ay[1:-1].any()
    # A belt reversal rebuilds the field (other y ranges); the invariant still holds.
    sim.set_belt_speeds([-0.5])
    sim.step(200)
    assert not sim._ay[1:-1].any()
    assert sim.density.min() >= 0.0
    assert sim.density.max() <= RHO_MAX * (1.0 + 1e-12)


def test_pusher_across_a_running_belt_matches_numpy_reference():
    """A pusher's moving face gives y velocities that change every step."""
    pusher = Actuator('push', 'pusher', (0.3, 0.17), (0.0, -1.0), 0.02, 0.1, (0.0, 0.3), 0.4,
                      0.0)
    cell = make_cell(region=(0.0, -0.15, 0.6, 0.15), variant='goettlich',
                     belts=[belt((0.0, 0.0), (0.6, 0.0), 0.3, 0.2)], actuators=[pusher])
    sim = MacroSim(cell)
    xs, _ = sim.grid.centres()
    sim.density[:] = np.where((xs > 0.1) & (xs < 0.4), 0.8 * RHO_MAX, 0.0)
    total = sim.total_parts()
    position = 0.0
    for _ in range(150):
        position += 0.4 * sim.dt
        sim.set_actuator_positions([position])
        ref = ReferenceSim(sim)
        sim.step(1)
        ref.step(1)
        assert np.abs(sim.density - ref.rho).max() <= 1e-11 * RHO_MAX
    assert abs(sim.balance_error(total)) <= 1e-12 * total
    assert not sim._ay[1:-1].any()
