"""MacroSim's interface: deposit, take, region reads, commands, determinism, errors."""

import numpy as np
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Obstacle
from conveyor_twin.macro import MacroSim
from .cells import belt, make_cell


def _sim(**kw):
    cell = make_cell(region=(0.0, -0.25, 1.0, 0.25),
                     belts=[belt((0.0, 0.0), (1.0, 0.0), 0.5, 0.5)],
                     obstacles=[Obstacle('peg', 'peg', ((0.5, 0.0),), radius=0.03)], **kw)
    return MacroSim(cell)


def test_default_cell_geometry():
    sim = MacroSim(load_cell(None))
    assert (sim.nx, sim.ny, sim.resolution) == (600, 50, 0.01)
    assert (sim.origin_x, sim.origin_y) == (0.0, -0.25)
    assert sim.density.shape == (50, 600) and sim.density.flags.c_contiguous
    assert sim.rho_max == pytest.approx(1.0 / (2.0 * np.sqrt(3.0) * 0.005 ** 2))
    assert sim.solid.sum() > 0                     # the deflector
    assert sim.variant == 'goettlich' and sim.scheme == 'upwind'


@pytest.mark.parametrize('radius', [0.003, 0.02, 0.05])
def test_deposit_adds_exactly_one_part(radius):
    sim = _sim()
    sim.deposit(0.205, 0.005, radius)
    assert sim.total_parts() == pytest.approx(1.0, rel=1e-14)
    assert sim.parts_deposited == 1.0
    occupied = np.count_nonzero(sim.density)
    assert occupied == 1 if radius < 0.005 else occupied > 4


def test_deposit_clipped_at_edge_and_solid_is_conserved():
    sim = _sim()
    sim.deposit(0.001, 0.249, 0.03, amount=2.5)            # corner: most of the disc is outside
    sim.deposit(0.5, 0.0, 0.01)                            # inside the peg: nearest fluid cell
    sim.deposit(0.47, 0.0, 0.02)                           # half on the peg
    assert sim.total_parts() == pytest.approx(4.5, rel=1e-14)
    assert sim.density[sim.solid != 0].sum() == 0.0
    kernel = np.array([[0.0, 1.0, 0.0], [1.0, 4.0, 1.0], [0.0, 1.0, 0.0]])
    sim.deposit(0.3, 0.0, kernel, amount=8.0)
    assert sim.total_parts() == pytest.approx(12.5, rel=1e-14)
    j, i = 25, 30
    assert sim.density[j, i] * sim.resolution ** 2 == pytest.approx(4.0, rel=1e-12)
    with pytest.raises(ValueError):
        sim.deposit(1.5, 0.0, 0.01)
    with pytest.raises(ValueError):
        sim.deposit(0.3, 0.0, np.ones((2, 2)))


def test_take_region_removes_and_returns():
    sim = _sim()
    sim.density[:, :] = 1000.0
    sim.density[sim.solid != 0] = 0.0
    total = sim.total_parts()
    inside = sim.region_parts((0.1, -0.1, 0.3, 0.1))
    assert inside == pytest.approx(1000.0 * 0.2 * 0.2, rel=1e-12)
    assert sim.take_region((0.1, -0.1, 0.3, 0.1)) == inside
    assert sim.region_parts((0.1, -0.1, 0.3, 0.1)) == 0.0
    assert sim.total_parts() == pytest.approx(total - inside, rel=1e-12)
    assert sim.balance_error(total) == pytest.approx(0.0, abs=1e-9)


def test_commands_rebuild_only_on_change_and_validate():
    sim = _sim()
    ux = sim.face_velocity[0]
    sim.set_belt_speeds([0.5])
    assert sim.face_velocity[0] is ux and ux[0, 1] == 0.5
    sim.set_belt_speeds([1.5])
    assert ux[0, 1] == 1.5
    assert sim.substeps == 1
    sim.set_belt_speeds([-20.0])       # 20 m/s, 1 cm cells, 1 ms, cfl 0.9: 3 substeps
    assert sim.substeps == 3
    with pytest.raises(ValueError):
        sim.set_belt_speeds([1.0, 2.0])
    with pytest.raises(ValueError):
        sim.set_actuator_positions([0.1])
    with pytest.raises(ValueError):
        sim.set_inflow(np.zeros(3))


def test_stopper_engages_at_its_height():
    sim = MacroSim(load_cell(None), variant='capped')
    k = sim.cell.actuator_index('stopper')
    positions = sim.actuator_positions
    base = sim.solid.sum()
    positions[k] = 0.0039
    sim.set_actuator_positions(positions)
    assert sim.solid.sum() == base
    positions[k] = 0.004
    sim.set_actuator_positions(positions)
    assert sim.solid.sum() == base + 2 * sim.ny     # two columns across the belt


def test_state_bytes_are_deterministic():
    def run(speed):
        sim = _sim(variant='goettlich')
        rates = np.zeros(sim.grid.n_boundary)
        rates[:sim.ny] = 40.0
        sim.set_inflow(rates)
        sim.step(300)
        sim.set_belt_speeds([speed])
        sim.deposit(0.7, 0.1, 0.01)
        sim.step(200)
        return sim.state_bytes()

    assert run(0.4) == run(0.4)
    assert run(0.4) != run(0.41)
