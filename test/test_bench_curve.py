"""``bench curve``: two scenes of the same area whose parts move with the surface, apart."""

import json
import math

import numpy as np
import pytest

from conveyor_twin.bench import curve
from conveyor_twin.cli.bench import BENCHES


def test_the_scenes_have_the_same_area_and_parts_ride_apart():
    straight, curved = curve.scene(False, 10), curve.scene(True, 10)
    a = straight.belts[0].width * straight.belts[0].length
    c = curved.belts[0].curve
    assert a == pytest.approx(0.25 * math.pi * (c.outer_radius ** 2 - c.inner_radius ** 2))
    for is_curved in (False, True):
        sim = curve.populated(is_curved, curve.DEFAULT_PARTS)
        sim.step(20)
        p = sim.parts_view()
        assert len(p) == curve.DEFAULT_PARTS
        # with the surface: speed omega r on the curve, the belt's on the straight
        speed = np.hypot(p.vx, p.vy)
        expected = (np.hypot(p.x, p.y) * curve.SPEED / curve.centre_radius() if is_curved
                    else curve.SPEED)
        assert speed == pytest.approx(expected, rel=1e-6)
    with pytest.raises(ValueError, match='at most'):
        curve.lattice(1000)


def test_the_verb_prints_both_medians_and_their_ratio(capsys):
    assert BENCHES['curve'] == 'conveyor_twin.bench.curve'
    assert curve.main(['--parts', '20', '--steps', '5', '--rounds', '1', '--json']) == 0
    result = json.loads(capsys.readouterr().out)
    assert result['ratio'] == result['curve_median_s'] / result['straight_median_s']
    assert len(result['straight_s']) == len(result['curve_s']) == 1
