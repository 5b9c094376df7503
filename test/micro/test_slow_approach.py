"""Discs side by side that approach at a speed whose square underflows (the remnants of a long
decay in a jam, kept by parts that leave it) step like discs that do not approach at all."""

import numpy as np
import pytest

from conveyor_twin.micro import MicroSim
from test.micro.conftest import disc, make_cell

R = 0.005           # m, the discs' radius
GAP = 1e-4          # m, within the speculative margin of a substep


def side_by_side(lateral: float) -> MicroSim:
    """Two discs on a running belt at the same x, a gap apart across it, both at rest (both
    slip alike), the upper one closing the gap at ``lateral`` [m/s]."""
    cell = make_cell(part_types=(disc(radius=R, mu_s=0.3, mu_k=0.3),), speed=1.0,
                     friction=0.4)
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.5, 0.0, 0.0)
    sim.spawn(0, 0.5, 2 * R + GAP, 0.0, vy=-lateral)
    return sim


@pytest.mark.parametrize('lateral', [1e-170, 1e-200, 1e-300, 1e-320, 1e-160])
def test_an_approach_too_slow_to_square_is_no_approach(lateral):
    sim = side_by_side(lateral)
    still = side_by_side(0.0)
    for _ in range(20):
        sim.step(1)     # the impact time divides by the squared speed (0.0 below 1e-162)
        still.step(1)
        v, w = sim.parts_view(), still.parts_view()
        for name in ('x', 'y', 'yaw', 'vx', 'vy', 'wz'):
            got = getattr(v, name)
            assert np.all(np.isfinite(got)), (name, got)
            assert np.allclose(got, getattr(w, name), rtol=0.0, atol=1e-12), (name, got)
    assert v.y[1] - v.y[0] == pytest.approx(2 * R + GAP, abs=1e-12)
