"""The fast hand-over kernels against their plain references (same results, bit for bit)."""

import numpy as np
import pytest

from conveyor_twin.coupling import handover as ho
from conveyor_twin.micro.state import P_X, P_Y


def _blocks_reference(macro: np.ndarray, tc: int, ny: int, nx: int) -> np.ndarray:
    ty, tx = np.nonzero(~macro)
    return np.stack([ty * tc, np.minimum(ny, (ty + 1) * tc), tx * tc,
                     np.minimum(nx, (tx + 1) * tc)], axis=1).astype(np.int64)


def _scan_order(blocks: np.ndarray) -> list:
    return [(j, i) for j0, j1, i0, i1 in blocks for j in range(j0, j1) for i in range(i0, i1)]


def test_merged_micro_blocks_keep_the_scan_order() -> None:
    rng = np.random.default_rng(3)
    for tc, ny, nx in ((1, 7, 13), (3, 10, 11), (2, 5, 9)):
        nty, ntx = -(-ny // tc), -(-nx // tc)
        for p in (0.0, 0.3, 0.8, 1.0):
            macro = rng.random((nty, ntx)) < p
            out = np.zeros((macro.size, 4), dtype=np.int64)
            m = ho.micro_blocks(macro, tc, ny, nx, out)
            ref = _blocks_reference(macro, tc, ny, nx)
            assert _scan_order(out[:m]) == _scan_order(ref)
            assert m <= max(1, len(ref))


def test_hold_back_over_runs_equals_the_full_sweep() -> None:
    rng = np.random.default_rng(5)
    ny, nx, h = 6, 15, 0.05
    active = (rng.random((ny, nx)) < 0.3).astype(np.uint8)
    solid = np.zeros((ny, nx), dtype=np.uint8)
    solid[2, 4] = 1
    vel = np.zeros((ny, nx, 2))
    vel[..., 0] = 0.5
    vel[4, :, :] = (0.0, -0.3)
    rho = rng.random((ny, nx)) * 30000.0
    x = rng.random(200) * nx * h
    y = rng.random(200) * ny * h
    closed = np.zeros((ny, nx), dtype=np.uint8)
    closed[:, 9:11] = 1  # a sensor window across the flow (never active)
    active[:, 8:11] = 0
    active[1, 8] = 1  # row 1: a macro cell right in front of the window
    runs = np.zeros((ny * nx, 3), dtype=np.int64)
    m = ho.inactive_runs(active, runs)
    a, b = rho.copy(), rho.copy()
    occ = np.zeros((ny, nx))
    ho.hold_back(a, active, solid, vel, 0.0, 0.0, h, 10000.0, x, y, 200, occ, (closed, 1))
    ho.hold_back_runs(b, runs, m, active, solid, vel, 0.0, 0.0, h, 10000.0, x, y, 200, occ,
                      (closed, 1))
    assert a.tobytes() == b.tobytes() and not np.array_equal(a, rho)
    assert a.sum() == pytest.approx(rho.sum(), rel=1e-12)
    # no density is left in the window (but rows 4 and 5: row 4 flows along -y and pushes into
    # row 5 after the backward sweep has passed it) ...
    window = closed == 1
    window[4:6, :] = False
    window[1, :] = False
    assert not a[window].any()
    # ... but in front of a macro cell it stays in the window's entrance cell
    assert a[1, 9] == rho[1, 9] + rho[1, 10] and a[1, 10] == 0.0


def test_a_window_entrance_is_as_deep_as_a_release_window_needs() -> None:
    ny, nx, h = 3, 14, 0.05
    active = np.zeros((ny, nx), dtype=np.uint8)
    active[:, 3:6] = 1  # a macro tile right in front of the window (flow along +x)
    active[2, :] = 0  # row 2: micro in front of the window
    solid = np.zeros((ny, nx), dtype=np.uint8)
    closed = np.zeros((ny, nx), dtype=np.uint8)
    closed[:, 6:11] = 1
    vel = np.zeros((ny, nx, 2))
    vel[..., 0] = 0.5
    rho = np.zeros((ny, nx))
    rho[:, 6:11] = 100.0
    runs = np.zeros((ny * nx, 3), dtype=np.int64)
    m = ho.inactive_runs(active, runs)
    occ = np.zeros((ny, nx))
    x = y = np.zeros(1)
    for depth in (1, 2, 3):
        a, b = rho.copy(), rho.copy()
        ho.hold_back(a, active, solid, vel, 0.0, 0.0, h, 1e4, x, y, 0, occ, (closed, depth))
        ho.hold_back_runs(b, runs, m, active, solid, vel, 0.0, 0.0, h, 1e4, x, y, 0, occ,
                          (closed, depth))
        assert a.tobytes() == b.tobytes() and a.sum() == pytest.approx(rho.sum(), rel=1e-12)
        # behind the macro tile the density stays in the first ``depth`` cells of the window
        # (the last of them takes what flowed further) ...
        expected = np.zeros(5)
        expected[:depth - 1] = 100.0
        expected[depth - 1] = 100.0 * (5 - depth + 1)
        assert np.array_equal(a[0, 6:11], expected) and np.array_equal(a[1, 6:11], expected)
        # ... and in front of a micro tile none of it enters the window
        assert not a[2, 6:11].any() and a[2, 5] == 500.0
    # a row of 2 w + 1 cells holding a part at ENTRANCE_FILL rho_max: one cell deep; large
    # parts on small cells: deeper, at most 2 w + 1
    assert ho.entrance_depth(1, 11547.0, 0.02) == 1
    assert ho.entrance_depth(2, 265.08, 0.02) == 3  # cans of 33 mm on 2 cm cells
    assert ho.entrance_depth(1, 100.0, 0.02) == 3
    assert ho.entrance_depth(2, 1.0 / (5 * ho.ENTRANCE_FILL * 0.02 ** 2), 0.02) == 1


def test_take_cells_and_deposit_match_the_references() -> None:
    rng = np.random.default_rng(7)
    rho = rng.random((8, 9))
    mask = rng.random((8, 9)) < 0.4
    a, b = rho.copy(), rho.copy()
    assert ho.take_mask(a, mask, 0.05) == ho.take_cells(b, np.flatnonzero(mask), 0.05)
    assert a.tobytes() == b.tobytes()
    active = np.ones((8, 9), dtype=np.uint8)
    solid = np.zeros((8, 9), dtype=np.uint8)
    before = rho.copy()
    for px, py, r in ((0.05, 0.05, 0.005), (0.2, 0.13, 0.03), (0.0999, 0.2, 0.012)):
        ho.deposit_disc(rho, active, solid, 0.0, 0.0, 0.05, px, py, r, 1.0)
    assert abs((rho - before).sum() * 0.05 ** 2 - 3.0) < 1e-12


def test_bucket_lookup_finds_exactly_the_near_parts() -> None:
    rng = np.random.default_rng(11)
    n = 500
    P = np.zeros((9, n))
    P[P_X] = rng.random(n) * 3.0 - 0.5  # some outside the box
    P[P_Y] = rng.random(n) * 1.2 - 0.1
    bbox = np.zeros(5)
    bbox[2] = 0.08
    bhead = np.zeros(64, dtype=np.int64)  # small: the bucket edge has to grow
    bnext = np.zeros(n, dtype=np.int64)
    ho.bucket_parts(P, n, 0.0, 0.0, 2.0, 1.0, bbox, bhead, bnext)
    assert bbox[2] >= 0.08 and bbox[3] * bbox[4] <= bhead.size
    near = np.zeros(n, dtype=np.int64)
    for x, y in rng.random((50, 2)) * (2.4, 1.1) - (0.2, 0.05):
        m = ho.near_parts(P, x, y, 0.079, bbox, bhead, bnext, near)
        ref = np.flatnonzero((np.abs(P[P_X] - x) < 0.079) & (np.abs(P[P_Y] - y) < 0.079))
        assert sorted(near[:m]) == list(ref)


def _front_grid():
    """A 6 x 8 grid, flow along +x, a sensor window (closed) in columns 5..6."""
    ny, nx, h = 6, 8, 0.1
    closed = np.zeros((ny, nx), dtype=np.uint8)
    closed[:, 5:7] = 1
    active = np.zeros((ny, nx), dtype=np.uint8)
    solid = np.zeros((ny, nx), dtype=np.uint8)
    vel = np.zeros((ny, nx, 2))
    vel[..., 0] = 0.5
    border = np.zeros((ny * nx, 2), dtype=np.int64)
    border = border[:ho.border_cells(closed, border)].copy()
    runs = np.zeros((ny * nx, 3), dtype=np.int64)
    m = ho.inactive_runs(active, runs)
    return h, closed, active, solid, vel, border, runs, m


def test_gather_fronts_collects_a_whole_part_spread_thin_in_front_of_a_window() -> None:
    h, closed, active, solid, vel, border, runs, m = _front_grid()
    hh = h * h
    assert {(int(j), int(i)) for j, i in border} == {(j, i) for j in range(6) for i in (4, 7)}
    rho = np.zeros((6, 8))
    rho[:, 4] = np.array([0.05, 0.3, 0.25, 0.2, 0.15, 0.05]) / hh  # 1.0 part, no 3 cells hold it
    before = rho.copy()
    assert ho.gather_fronts(rho, active, closed, solid, vel, h, border, 1, runs, m) == 1
    assert rho[:, 4].sum() * hh == pytest.approx(1.0, abs=1e-12)
    assert np.count_nonzero(rho[:, 4]) == 1 and rho[2, 4] > 0.0  # at the mass centre (row 2.2)
    # a front that a release window can take as it is, or that holds less than a part while
    # more is coming (the row upstream), is left alone
    for front in ([0.0, 0.5, 0.5, 0.2, 0.0, 0.0], [0.1, 0.2, 0.2, 0.2, 0.0, 0.0]):
        rho = np.zeros((6, 8))
        rho[:, 4] = np.array(front) / hh
        rho[2, 1] = 2.0 / hh  # more than a part coming
        copy = rho.copy()
        assert ho.gather_fronts(rho, active, closed, solid, vel, h, border, 1, runs, m) == 0
        assert np.array_equal(rho, copy)
    # a remainder with nothing coming moves past the window (columns 5..6) and flows on
    rho = np.zeros((6, 8))
    rho[:, 4] = np.array([0.1, 0.2, 0.2, 0.2, 0.0, 0.0]) / hh
    assert ho.gather_fronts(rho, active, closed, solid, vel, h, border, 1, runs, m) == 1
    assert not rho[:, 4].any() and rho[:, 7] * hh == pytest.approx([0.1, 0.2, 0.2, 0.2, 0, 0])
    assert before.sum() > 0


def test_gather_fronts_completes_a_nearly_whole_front_from_the_thin_tail_upstream() -> None:
    h, closed, active, solid, vel, border, runs, m = _front_grid()
    hh = h * h
    rho = np.zeros((6, 8))
    rho[:, 4] = np.array([0.0, 0.3, 0.3, 0.2, 0.195, 0.0]) / hh  # 0.995 parts
    rho[1:5, 0:3] = 0.005 / 12 / hh  # the tail: 0.005 parts over 12 cells upstream
    total = rho.sum() * hh
    assert ho.gather_fronts(rho, active, closed, solid, vel, h, border, 1, runs, m) == 1
    assert rho.sum() * hh == pytest.approx(total, abs=1e-12)
    assert rho[:, 4].max() * hh == pytest.approx(1.0, abs=1e-12)
    assert rho[:, 0:3].sum() * hh == pytest.approx(0.0, abs=1e-12)
