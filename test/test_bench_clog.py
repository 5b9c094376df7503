"""``bench clog``: the narrowed gap, the release, the overlap measure, and a tiny run of both
engines whose figures must be in range (not its wall-clock times)."""

import json

import numpy as np
import pytest

from conveyor_twin.bench import clog
from conveyor_twin.cell import load_cell


@pytest.mark.parametrize('gap', [2, 3.5, 6])
def test_gap_is_narrowed_to_the_asked_clear_width(gap):
    base = load_cell(None)
    cell = clog.gap_cell(gap, base)
    d = 2.0 * base.part_types[0].radius
    assert clog.clearance(cell) == pytest.approx(gap * d, abs=1e-9)
    k = clog._deflector(cell)
    # the deflector keeps its upstream end and its direction
    (ax, ay), (bx, by) = cell.obstacles[k].points
    (a0x, a0y), (b0x, b0y) = base.obstacles[k].points
    assert (ax, ay) == (a0x, a0y)
    cross = (bx - ax) * (b0y - a0y) - (by - ay) * (b0x - a0x)
    assert cross == pytest.approx(0.0, abs=1e-12)
    assert not (cell.sources or cell.sinks or cell.actuators or cell.light_barriers)


def test_release_is_upstream_and_free_of_overlaps():
    cell = clog.gap_cell(3)
    r = cell.part_types[0].radius
    pts = clog.release_positions(cell, 150, seed=4)
    assert pts.shape == (150, 2)
    assert clog.deepest_overlap(pts, r) == 0.0
    assert np.abs(pts[:, 1]).max() < 0.25 - r
    deflector = cell.obstacles[clog._deflector(cell)]
    assert pts[:, 0].max() < min(p[0] for p in deflector.points) - r
    assert not np.array_equal(pts, clog.release_positions(cell, 150, seed=5))
    assert np.array_equal(pts, clog.release_positions(cell, 150, seed=4))


def test_deepest_overlap_equals_all_pairs():
    rng = np.random.default_rng(3)
    r = 0.005
    for _ in range(20):
        pts = rng.uniform(0.0, 0.12, (60, 2))
        d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        d[np.diag_indices(60)] = np.inf
        assert clog.deepest_overlap(pts, r) == pytest.approx(max(0.0, 2 * r - d.min()),
                                                              abs=1e-15)


def test_tiny_run_of_both_engines_reports_figures_in_range(capsys):
    pytest.importorskip('pymunk')
    assert clog.main(['--gaps', '6', '--seeds', '2', '--parts', '30', '--window', '1.5',
                      '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['parts'] == 30 and report['seeds'] == 2 and report['window_s'] == 1.5
    assert report['quiet_s'] == 1.0 and report['pymunk']['slop_m'] == clog.PYMUNK_SLOP
    entry = report['gaps']['6']
    assert entry['gap_m'] == pytest.approx(0.06)
    for engine in ('ours', 'pymunk'):
        runs = entry[engine]
        assert len(runs) == 2
        for run in runs:
            assert 0 <= run['passed'] <= 30
            assert run['fraction_passed'] == run['passed'] / 30
            assert 0.0 <= run['max_overlap_pct'] < 100.0
            # a six-diameter gap and a single row of parts: they flow, nothing clogs
            assert run['passed'] > 0 and not run['stopped']
            assert 0.5 <= run['last_pass_s'] <= 1.5
        s = entry['summary'][engine]
        assert s['runs'] == 2 and s['stopped'] == 0 and s['clog_probability'] == 0.0
        assert 0.0 < s['fraction_passed_min'] <= s['fraction_passed_mean'] <= 1.0
    assert 'To, Lai and Pak' in report['literature']


def test_wilson_interval():
    assert clog.wilson(0, 10)[0] == 0.0 and clog.wilson(10, 10)[1] == 1.0
    lo, hi = clog.wilson(5, 10)
    assert lo < 0.5 < hi and lo == pytest.approx(1.0 - hi)
    assert clog.wilson(1, 10) == pytest.approx(tuple(1.0 - b for b in clog.wilson(9, 10)[::-1]))


def test_a_gap_that_is_not_positive_or_wider_than_the_cells_is_refused():
    for gap in (0.0, -1.0, 15.0):
        with pytest.raises(ValueError):
            clog.gap_cell(gap)
