"""The fast hand-over kernels against their plain references (same results, bit for bit)."""

import numpy as np

from conveyor_twin.coord import handover as ho
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
    runs = np.zeros((ny * nx, 3), dtype=np.int64)
    m = ho.inactive_runs(active, runs)
    a, b = rho.copy(), rho.copy()
    occ = np.zeros((ny, nx))
    ho.hold_back(a, active, solid, vel, 0.0, 0.0, h, 10000.0, x, y, 200, occ)
    ho.hold_back_runs(b, runs, m, solid, vel, 0.0, 0.0, h, 10000.0, x, y, 200, occ)
    assert a.tobytes() == b.tobytes() and not np.array_equal(a, rho)


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
