"""Penalty (spring-damper) contacts, the activity metric and the stiffness picker."""

import numpy as np
import pytest

from conveyor_twin.micro import MicroSim
from conveyor_twin.micro.activity import pick_contact_stiffness, spring_ratio
from conveyor_twin.micro.sim import penalty_substep
from test.micro.conftest import disc, make_cell, wall


def test_penalty_head_on_conserves_momentum_and_separates():
    # undamped spring contact between equal discs is elastic: velocities swap
    cell = make_cell(part_types=(disc(),), friction=0.0, contact='penalty',
                     penalty_stiffness=1e5, penalty_damping=0.0)
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, [0.5, 0.52], 0.0, 0.0, vx=[0.5, -0.5])
    assert sim.substeps == 0
    sim.step(100)
    assert sim.substeps == int(np.ceil(cell.settings.step / penalty_substep(cell, 1e5, 0.0)))
    v = sim.parts_view()
    assert v.vx.sum() == pytest.approx(0.0, abs=1e-12)
    # explicit integration at omega h = 0.5: exit speed within a few per cent
    assert v.vx[0] == pytest.approx(-0.5, rel=5e-2) and v.vx[1] == pytest.approx(0.5, rel=5e-2)
    act = sim.activity()
    # the spring stored and returned the kinetic energy: activity 2 * (1/2 m v^2) * 2 parts
    assert act['contact_springs'] == pytest.approx(2 * 0.5 * 0.01 * 0.25 * 2, rel=0.1)
    assert act['contact_dampers'] == 0.0


def test_stiffer_springs_are_less_active_in_a_resting_jam():
    cell = make_cell(speed=0.3, obstacles=(wall('stop', (0.6, -0.25), (0.6, 0.25),
                                                thickness=0.01),))
    positions = np.array([[0.58 - 0.0102 * k, 0.0] for k in range(8)])
    picks = pick_contact_stiffness(cell, seed=0, duration=0.05, settle=0.1,
                                   positions=positions, stiffness=1e3, fraction=0.01)
    assert picks.ratio <= 0.01
    ks = [k for k, _ in picks.trials]
    ratios = [r for _, r in picks.trials]
    assert ks == sorted(ks)
    if len(ratios) > 1:
        assert ratios[-1] < ratios[0]
    assert spring_ratio(picks.activity) == picks.ratio


def test_impact_restitution_exact_for_impulses_step_dependent_for_springs():
    from conveyor_twin.bench import micro as bench
    # the impulse model's restitution is the part's, at any step
    assert bench.impact_restitution('impulse', 1e-3) == pytest.approx(0.4, abs=1e-12)
    # stainless steel line contact of the 10 mm high discs, k = (pi / 4) E* L
    k = bench.seed_stiffness(bench.scene(2))
    assert k == pytest.approx(8.28e8, rel=1e-2)
    # penalty springs: the error grows with omega dt; 12 steps per period keep it near 5 %
    res = bench.largest_accurate_step(1e5, 5.0)
    errors = list(res['errors'].values())
    assert errors == sorted(errors, reverse=True) and errors[-1] <= bench.IMPACT_TOLERANCE
    f = bench.contact_frequency(bench.scene(2), 1e5)
    rule = 1.0 / (bench.STEPS_PER_PERIOD * f)
    e = bench.impact_restitution('penalty', rule, penalty_stiffness=1e5, penalty_damping=5.0)
    assert abs(e - res['converged_restitution']) < 0.1 * res['converged_restitution']


def test_placed_parts_take_the_velocity_of_the_belt_under_them_on_any_belt_shape():
    from pathlib import Path

    import yaml

    from conveyor_twin.cell.loader import cell_from_mapping
    from conveyor_twin.micro.activity import belt_velocity_at, run_activity
    path = Path(__file__).resolve().parents[2] / 'conveyor_twin/cell/examples/l_line.yaml'
    d = yaml.safe_load(path.read_text())
    d['belts'] = [d['belts'][1], d['belts'][0], d['belts'][2]]   # the curve first
    d['sources'] = []
    cell = cell_from_mapping(d)
    assert belt_velocity_at(cell, (1.0, 0.0)) == pytest.approx((0.5, 0.0))      # infeed
    assert belt_velocity_at(cell, (2.6, 1.5)) == pytest.approx((0.0, 0.5))      # outfeed
    # on the bend, 0.7 m from its centre (2.0, 0.6) and 30 deg into it: omega x r with
    # omega = 0.5 / 0.6 rad/s (the speed is given on the centre line, radius 0.6 m)
    omega, rx, ry = 0.5 / 0.6, 0.7 * np.sin(np.pi / 6), -0.7 * np.cos(np.pi / 6)
    assert belt_velocity_at(cell, (2.0 + rx, 0.6 + ry)) == pytest.approx((-omega * ry,
                                                                          omega * rx))
    assert belt_velocity_at(cell, (1.0, 1.0)) == (0.0, 0.0)                     # off the belts
    positions = np.array([[2.0 + 0.7 * np.sin(a), 0.6 - 0.7 * np.cos(a)]
                          for a in np.linspace(0.1, 1.2, 5)])
    activity = run_activity(cell, cell.micro.penalty_stiffness, cell.micro.penalty_damping,
                            seed=1, duration=0.02, positions=positions)
    assert activity and all(np.isfinite(v) for v in activity.values())
