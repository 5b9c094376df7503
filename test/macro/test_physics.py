"""Physics of the macro model: queues, stoppers, deflectors, belt reversal, pushers."""

import numpy as np
import pytest

from conveyor_twin.cell.model import Actuator, Obstacle
from conveyor_twin.macro import MacroSim
from .cells import belt, make_cell, RHO_MAX

U = 0.5          # m/s belt speed
WIDTH = 0.1      # m belt width
H = 0.01


def _stopper(position=0.008):
    return Actuator('stop', 'stopper', (0.8, 0.0), (0.0, 1.0), 0.12, 0.01, (0.0, 0.008), 0.1,
                    position, engage_height=0.004)


def _strip(variant='capped', scheme='upwind', **kw):
    cell = make_cell(region=(0.0, -0.05, 1.0, 0.05),
                     belts=[belt((0.0, 0.0), (1.0, 0.0), WIDTH, U)],
                     actuators=[_stopper()], variant=variant, scheme=scheme, **kw)
    return MacroSim(cell)


def _feed(sim, rho_in):
    rates = np.zeros(sim.grid.n_boundary)
    rates[:sim.ny] = rho_in * U * sim.resolution          # parts/s per left face
    sim.set_inflow(rates)


def _queue_length(sim, rho_in):
    """Length [m] of the packed region upstream of the stopper (middle row)."""
    row = sim.density[sim.ny // 2]
    return np.count_nonzero(row > 0.5 * (rho_in + sim.rho_max)) * sim.resolution


@pytest.mark.parametrize('variant,tol', [('capped', 2.5 * H), ('goettlich', 0.15 * 0.2)])
def test_queue_grows_at_rankine_hugoniot_speed(variant, tol):
    """A closed stopper: the queue front moves upstream at u rho_in / (rho_max - rho_in)."""
    rho_in = 0.4 * RHO_MAX
    sim = _strip(variant)
    _feed(sim, rho_in)
    sim.step(2000)                                  # front reached the stopper at t = 1.6 s
    l1 = _queue_length(sim, rho_in)
    sim.step(600)
    l2 = _queue_length(sim, rho_in)
    speed = U * rho_in / (RHO_MAX - rho_in)         # 1/3 m/s
    assert l1 > 0.05
    assert abs((l2 - l1) - speed * 0.6) <= tol
    # Nothing passed the closed stopper; the queue holds what came in.
    assert sim.region_parts((0.81, -0.05, 1.0, 0.05)) == 0.0
    assert sim.parts_out == 0.0
    assert sim.total_parts() == pytest.approx(sim.parts_in, rel=1e-12)


def test_released_queue_leaves_at_belt_speed_as_a_block():
    """Opening the stopper: the packed queue moves on at belt speed (capped flux is u rho)."""
    rho_in = 0.4 * RHO_MAX
    sim = _strip('capped')
    _feed(sim, rho_in)
    sim.step(2600)
    _feed(sim, 0.0)
    queue = sim.total_parts()
    sim.set_actuator_positions([0.0])
    assert sim.solid.sum() == 0
    # The front of the block needs (1.0 - 0.81) / U = 0.38 s to reach the exit; then the packed
    # block leaves at u rho_max W per second.
    sim.step(300)
    assert sim.parts_out < 1e-2 * queue          # only the diffused front (upwind) so far
    sim.step(300)
    rates = []
    for _ in range(5):
        sim.step(20)
        rates.append(sim.outflow.sum() / (20 * sim.dt))
    # The packed middle of the block leaves at u rho_max W (its ends are smeared by upwind).
    assert np.allclose(rates, U * RHO_MAX * WIDTH, rtol=0.03)
    assert rates[-1] == pytest.approx(U * RHO_MAX * WIDTH, rel=0.01)


def test_belt_reversal_moves_material_back_and_out_on_the_other_side():
    cell = make_cell(region=(0.0, -0.05, 1.0, 0.05),
                     belts=[belt((0.0, 0.0), (1.0, 0.0), WIDTH, U)])
    sim = MacroSim(cell)
    xs, _ = sim.grid.centres()
    sim.density[:] = 2000.0 * np.exp(-((xs - 0.5) / 0.05) ** 2)
    total = sim.total_parts()

    def centroid():
        return float((sim.density * xs).sum() / sim.density.sum())

    c0 = centroid()
    sim.step(300)                                     # 0.15 m downstream
    assert centroid() - c0 == pytest.approx(0.15, abs=1e-9)
    sim.set_belt_speeds([-U])
    assert sim.face_velocity[0][0, 5] == -U
    sim.step(300)
    assert centroid() == pytest.approx(c0, abs=1e-9)
    sim.step(2500)                                    # off the left edge
    assert sim.parts_out == pytest.approx(total, rel=1e-6)   # all but the far tail
    left = sim.outflow_total[:sim.ny].sum()
    assert left == pytest.approx(sim.parts_out, rel=1e-9)   # the rest: the far tail, right
    assert sim.outflow_total[2 * sim.ny:].sum() == 0.0      # nothing over the side edges


@pytest.mark.parametrize('variant', ['capped', 'goettlich'])
def test_deflector_redirects_to_the_gap_and_passes_the_inflow(variant):
    """The test rig's deflector (Hoher et al.): material slides along it, out through the gap."""
    deflector = Obstacle('d', 'deflector', ((2.75, 0.25), (3.1, -0.1)), thickness=0.01)
    cell = make_cell(region=(2.4, -0.25, 3.6, 0.25), variant=variant,
                     belts=[belt((0.0, 0.0), (6.0, 0.0), 0.5, U)], obstacles=[deflector])
    sim = MacroSim(cell)
    rho_in = 0.1 * RHO_MAX                           # 250 parts/s
    _feed(sim, rho_in)
    sim.step(8000)
    # Steady state: what comes in goes out, all of it through the right edge below the gap.
    n_out = sim.parts_out
    sim.step(1000)
    rate = (sim.parts_out - n_out) / 1.0
    inflow = rho_in * U * 0.5
    assert rate == pytest.approx(inflow, rel=0.02)
    ys = sim.grid.boundary_faces()[0][sim.ny:2 * sim.ny, 1]
    right = sim.outflow_total[sim.ny:2 * sim.ny]
    assert right[ys > -0.1 + H].sum() <= 1e-9 * right.sum()
    assert sim.region_parts((3.2, -0.08, 3.6, 0.25)) <= 1e-9 * sim.total_parts()
    # A queue formed along the deflector; the bound holds.
    assert sim.density.max() <= RHO_MAX * (1.0 + 1e-12)
    assert sim.density.max() >= 0.99 * RHO_MAX


def test_pusher_sweeps_material_off_the_belt_edge():
    pusher = Actuator('push', 'pusher', (0.3, 0.27), (0.0, -1.0), 0.02, 0.15, (0.0, 0.6), 0.8,
                      0.0)
    cell = make_cell(region=(0.0, -0.25, 0.6, 0.25),
                     belts=[belt((0.0, 0.0), (0.6, 0.0), 0.5, 0.0)],
                     actuators=[pusher])
    sim = MacroSim(cell)
    xs, _ = sim.grid.centres()
    sim.density[:] = np.where((xs > 0.15) & (xs < 0.45), 0.5 * RHO_MAX, 0.0)
    total = sim.total_parts()
    swept = sim.region_parts((0.235, -0.25, 0.365, 0.25))      # columns fully under the paddle
    position = 0.0
    for _ in range(750):                                         # 0.75 s at 0.8 m/s
        position = min(0.6, position + 0.8 * sim.dt)
        sim.set_actuator_positions([position])
        sim.step(1)
    assert sim.region_parts((0.235, -0.25, 0.365, 0.25)) <= 1e-9 * total
    assert sim.parts_out >= swept * (1.0 - 1e-9)
    bottom = sim.outflow_total[2 * sim.ny:2 * sim.ny + sim.nx].sum()
    assert bottom == pytest.approx(sim.parts_out, rel=1e-12)
    assert abs(sim.balance_error(total)) <= 1e-12 * total
    assert sim.density.min() >= 0.0
    # Beyond the paddle's edges and corner band (one cell) nothing moved.
    assert sim.region_parts((0.15, -0.25, 0.195, 0.25)) == pytest.approx(
        0.05 / 0.30 * total, rel=1e-9)
