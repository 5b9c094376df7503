"""The release and gathering kernels against their plain-Python references (bit for bit)."""

import copy

import numpy as np

from conveyor_twin.coupling import handover as ho
from conveyor_twin.coupling.handover.reference import gather_fronts_ref, release_windows_ref
from conveyor_twin.cell.model import Obstacle, ObstacleKind
from conveyor_twin.coupling.region import lattice
from conveyor_twin.micro.sim import MicroSim
from test.micro.conftest import disc, make_cell

H = 0.02
NY, NX = 20, 40
OX, OY = 0.0, -0.2


def _gather_case(seed: int):
    rng = np.random.default_rng(seed)
    vel = np.zeros((NY, NX, 2))
    vel[..., 0] = 0.5
    vel[rng.random((NY, NX)) < 0.1] = (0.0, 0.4)   # some cells flow along y
    vel[rng.random((NY, NX)) < 0.03] = 0.0          # and some are at rest
    closed = np.zeros((NY, NX), dtype=np.uint8)
    closed[:, 20:22] = 1                             # a window across the flow
    closed[3:5, 30:34] = 1                           # and one along it
    active = (rng.random((NY, NX)) < 0.2).astype(np.uint8)
    active[closed == 1] = 0
    solid = (rng.random((NY, NX)) < 0.03).astype(np.uint8)
    solid[closed == 1] = 0
    rho = np.zeros((NY, NX))
    thin = rng.random((NY, NX)) < 0.5
    rho[thin] = rng.random(int(thin.sum())) * 0.4 / (H * H)
    rho[:, 19] *= rng.random() * 2.0                 # the fronts: from a trace to a part
    rho[:, 8:19] *= rng.random() < 0.5               # with or without something coming
    return rho, active, closed, solid, vel


def test_gather_fronts_equals_its_reference() -> None:
    changed = 0
    for seed in range(40):
        rho, active, closed, solid, vel = _gather_case(seed)
        border = np.zeros((NY * NX, 2), dtype=np.int64)
        border = border[:ho.border_cells(closed, border)].copy()
        runs = np.zeros((NY * NX, 3), dtype=np.int64)
        m = ho.inactive_runs(active, runs)
        for w in (0, 1, 2):
            a, b = rho.copy(), rho.copy()
            n_kernel = ho.gather_fronts(a, active, closed, solid, vel, H, border, w, runs, m)
            n_ref = gather_fronts_ref(b, active, closed, solid, vel, H, w)
            assert n_kernel == n_ref
            assert a.tobytes() == b.tobytes()
            changed += n_kernel
    assert changed > 40  # the cases gather, complete and pass remainders


def _release_case(seed: int):
    rng = np.random.default_rng(seed)
    radius = 0.005
    # a peg and a wall inside the grid: spots on them are refused by the placement itself
    obstacles = (Obstacle(name='peg', kind=ObstacleKind.PEG, points=((0.25, 0.0),), radius=0.04),
                 Obstacle(name='wall', kind=ObstacleKind.WALL, points=((0.5, -0.1), (0.6, 0.1)),
                          thickness=0.01))
    cell = make_cell(part_types=(disc(radius=radius, name='a'), disc(radius=0.004, name='b')),
                     obstacles=obstacles, length=1.0, width=0.4, capacity=2000)
    sim = MicroSim(cell, seed=1)
    n = 150
    sim.spawn(0, rng.random(n) * 0.8, rng.random(n) * 0.36 - 0.18, 0.0, 0.5, 0.0, strict=False)
    active = (rng.random((NY, NX)) < 0.15).astype(np.uint8)
    acc = rng.random((NY, NX)) ** 4 * 1.5 / (H * H)
    thr = rng.random((NY, NX)) * 0.3
    ranges = np.array([[0, NY, 0, 20], [0, 10, 20, NX], [10, NY, 20, NX]], dtype=np.int64)
    vel = np.zeros((NY, NX, 2))
    vel[..., 0] = 0.5
    vel[:, 30:, 1] = 0.2
    d = 2.0 * radius + 1e-4
    offsets = lattice(1.5 * H, d)
    fifo = rng.integers(0, 2, 64).astype(np.int64)
    fstate = np.array([5, 40, 0], dtype=np.int64)
    s = sim.state
    window = (acc, active, H * H, thr, ranges)
    spots = (OX, OY, H, vel, offsets, d, 1.0, 0.0, True, np.array([OX, OY, H]), active)
    zone = (fifo, fstate, np.zeros(2, dtype=np.int64), np.array([0.3, 12345.0]))
    micro = (s.counters, s.ids, s.part_type, s.P, sim.pt, sim.shapes, sim.shape_verts,
             sim.act_state, sim.act_verts, sim._va, sim._vb, sim._out)
    return window, spots, zone, micro


def test_release_windows_equals_its_reference() -> None:
    released = failed = 0
    for seed in range(6):
        for w in (1, 2):
            for max_fail in (3, 1000):
                window, spots, zone, micro = _release_case(seed)
                state = copy.deepcopy((window, zone, micro))
                rot = np.array([seed], dtype=np.int64)
                cap = micro[3].shape[1]
                scratch = (np.zeros(5), rot.copy(), np.zeros(cap, dtype=np.int64),
                           np.zeros(ho.BUCKETS, dtype=np.int64), np.zeros(cap, dtype=np.int64))
                res = ho.release_windows(window, w, spots, max_fail, scratch, zone, micro)
                rwindow, rzone, rmicro = state
                rres = release_windows_ref(rwindow, w, spots, max_fail, rot, rzone, rmicro)
                assert res.tolist() == rres.tolist()
                assert scratch[1].tolist() == rot.tolist()
                for fast, ref in zip(window + zone + micro, rwindow + rzone + rmicro):
                    assert np.asarray(fast).tobytes() == np.asarray(ref).tobytes()
                released += int(res[0])
                failed += int(res[1])
    assert released > 100 and failed > 0  # parts placed, spots refused by the placement
