"""The compiled contact kernel against the slow reference."""

import dataclasses
import math

import numpy as np
import pytest

from conveyor_twin.micro import MicroSim
from conveyor_twin.micro.collide import box_vertices, collide
from conveyor_twin.micro.contacts.impulses import sweep_limit
from conveyor_twin.micro.contacts import (CT_BVX, CT_BVY, CT_BW, CT_E, CT_KA, CT_KB, CT_MU_K,
                                          CT_MU_S, CT_NX, CT_NY, CT_RAX, CT_RAY, CT_RBX, CT_RBY,
                                          CT_DEPTH, CT_V_T, detect, limit_energy, MP_DT,
                                          MP_BOUNCE_PASSES, MP_BOUNCE_TOLERANCE, MP_MAX_SWEEPS,
                                          MP_SPEC_MAX, MP_SWEEP_WORK, MP_TOLERANCE,
                                          prepare_contacts, PV_KA, PV_KB, PV_LN,
                                          PV_LT, restitute, solve_impulses, update_pairs)
from conveyor_twin.micro.kernel import CF_PASSES, CF_SKIN
from conveyor_twin.micro.reference import box_core, collide_ref, sweeps_ref
from conveyor_twin.micro.state import PT_INV_INERTIA, PT_INV_MASS
from test.micro.conftest import box, disc, make_cell, wall


def random_shape(rng, kind):
    c = rng.uniform(-0.01, 0.01, 2)
    if kind == 'disc':
        return np.array([c]), rng.uniform(0.002, 0.008)
    if kind == 'capsule':
        phi = rng.uniform(0, 2 * math.pi)
        h = rng.uniform(0.0, 0.02)
        d = np.array([math.cos(phi), math.sin(phi)]) * h
        return np.array([c - d, c + d]), rng.uniform(0.0, 0.004)
    out = np.zeros((4, 2))
    box_vertices(c[0], c[1], rng.uniform(-math.pi, math.pi), rng.uniform(0.002, 0.012),
                 rng.uniform(0.002, 0.008), out)
    assert np.allclose(out, box_core(c[0], c[1], math.atan2(*(out[1] - out[0])[::-1]),
                                     2 * np.linalg.norm(out[1] - out[0]) / 2,
                                     np.linalg.norm(out[3] - out[0])))
    return out, 0.0


@pytest.mark.parametrize('kinds', [('disc', 'disc'), ('disc', 'capsule'), ('disc', 'box'),
                                   ('box', 'disc'), ('box', 'box'), ('box', 'capsule'),
                                   ('capsule', 'box')])
def test_near_phase_matches_reference(kinds):
    rng = np.random.default_rng(7)
    out = np.zeros(8)
    touching = 0
    for _ in range(400):
        (va, ra), (vb, rb) = random_shape(rng, kinds[0]), random_shape(rng, kinds[1])
        count = collide(va, len(va), ra, vb, len(vb), rb, out)
        ref = collide_ref((va, ra), (vb, rb))
        if ref is None or ref[1] < 1e-9:
            assert count == 0 or out[4:5 + 3 * (count - 1):3].max() < 1e-9
            continue
        if ref[1] < 1e-7:
            continue
        assert count >= 1
        touching += 1
        depth = max(out[4 + 3 * k] for k in range(count))
        assert depth == pytest.approx(ref[1], abs=1e-9)
        assert out[:2] == pytest.approx(ref[0], abs=1e-6)
    assert touching > 50


@pytest.mark.parametrize('budget', ['fixed', 'work', 'partial'])
def test_impulse_sweeps_match_reference(budget):
    """``fixed``: 3 sweeps or the tolerance; ``work``: a budget of 6 sweeps' visits, no
    tolerance, so the sweeps the budget buys beyond the 3 count; ``partial``: that budget and
    the tolerance, so partial sweeps visit the contacts of the parts still moving only."""
    cell = make_cell(part_types=(disc(restitution=0.4, mu_s=0.3, mu_k=0.2),
                                 box(length=0.016, width=0.008)),
                     obstacles=(wall('w', (0.2, -0.1), (0.4, -0.1), thickness=0.004),))
    sim = MicroSim(cell, seed=0)
    rng = np.random.default_rng(3)
    placed = 0
    while placed < 40:
        ids = sim.spawn(int(rng.integers(2)), rng.uniform(0.25, 0.35), rng.uniform(-0.1, -0.03),
                        rng.uniform(-3, 3), vx=rng.normal(scale=0.5), vy=rng.normal(scale=0.5),
                        wz=rng.normal(scale=5), strict=False)
        placed += int(ids[0] != 0)
    # step forward so contacts exist, then compare one sweep set on the detected contacts
    sim.step(30)
    s = sim.state
    n = s.n
    x, y, yaw, vx, vy, wz = s.P[:6]
    update_pairs(n, s.ids, s.part_type, x, y, sim.pt, sim.grid.gpar, sim.grid.gdim,
                 sim._cell_table, sim._cell_items, sim._part_cell, sim._cand, sim._nbr,
                 sim._pos0, (sim.cfg[CF_SKIN], sim.mp[MP_SPEC_MAX]))
    parts, _model, drives, grid, statics, contact_arrays = sim._args[:6]
    nc = detect(n, parts, sim.pt, grid, statics, drives, contact_arrays, sim.mp)
    assert nc >= 5
    ct, cidx, prev = sim._ct, sim._cidx, sim._prev
    # a previous substep that had every other contact (and one more that is gone)
    warm = {}
    rows = []
    for c in range(0, nc, 2):
        ln, lt = rng.uniform(0.0, 1e-4), rng.normal(scale=3e-5)
        warm[c] = (ln, lt)
        rows.append((ct[c, CT_KA], ct[c, CT_KB], ln, lt))
    rows.insert(1, (rows[0][0], rows[0][1] + 0.5, 1.0, 1.0))
    prev[-1, 0] = len(rows)
    for k, (ka, kb, ln, lt) in enumerate(rows):
        prev[k, [PV_KA, PV_KB, PV_LN, PV_LT]] = ka, kb, ln, lt
    contacts = [dict(a=int(cidx[c, 0]), b=int(cidx[c, 1]), n=ct[c, [CT_NX, CT_NY]],
                     ra=ct[c, [CT_RAX, CT_RAY]], rb=ct[c, [CT_RBX, CT_RBY]], e=ct[c, CT_E],
                     mu_s=ct[c, CT_MU_S], mu_k=ct[c, CT_MU_K], v_t=ct[c, CT_V_T],
                     bv=ct[c, [CT_BVX, CT_BVY]], bw=ct[c, CT_BW], depth=ct[c, CT_DEPTH],
                     ln=warm.get(c, (0, 0))[0],
                     lt=warm.get(c, (0, 0))[1]) for c in range(nc)]
    v = np.stack([vx[:n], vy[:n]], 1).copy()
    w = wz[:n].copy()
    types = s.part_type[:n]
    # the energy an island may gain (surface friction's heat), here below 0 on some parts so
    # that the limit acts on some islands and not on others (the arithmetic is the same)
    heat = rng.uniform(-1e-4, 1e-5, size=n)
    mp = sim.mp.copy()
    mp[MP_SWEEP_WORK] = 0.0
    if budget != 'fixed':
        mp[MP_SWEEP_WORK] = 6 * nc + 1
        mp[MP_MAX_SWEEPS] = 256
    if budget == 'work':
        mp[MP_TOLERANCE] = 0.0
    stats = {}
    impulses = sweeps_ref(contacts, v, w, sim.pt[types, PT_INV_MASS],
                          sim.pt[types, PT_INV_INERTIA], passes=3, heat=heat, h=mp[MP_DT],
                          tolerance=mp[MP_TOLERANCE], bounce_passes=int(mp[MP_BOUNCE_PASSES]),
                          bounce_tolerance=mp[MP_BOUNCE_TOLERANCE],
                          work=int(mp[MP_SWEEP_WORK]), max_passes=int(mp[MP_MAX_SWEEPS]),
                          stats=stats)
    v0 = (vx[:n].copy(), vy[:n].copy(), wz[:n].copy())
    found, bounces = prepare_contacts(nc, ct, cidx, s.part_type, sim.pt, mp, vx, vy, wz, *v0,
                                      prev)
    assert found == len(warm)
    sweeps = solve_impulses(nc, ct, cidx, s.part_type, vx, vy, wz, sim.pt, 3, mp, sim.acc,
                            prev, contact_arrays[8])
    assert sweeps == stats['full_sweeps']
    # the visits of 3 or 6 full sweeps are the budget; partial sweeps' visits count too
    limit = 3 if budget == 'fixed' else 6
    assert stats['visits'] < (limit + 1) * nc   # the last sweep may cross the budget
    if budget == 'work':        # no tolerance: the whole budget is spent
        assert stats['visits'] >= limit * nc and sweeps < limit
    if budget == 'partial':     # partial sweeps ran and left out the parts that had settled
        partial = stats['sweeps'] - stats['full_sweeps']
        assert 0 < stats['partial_visits'] < partial * nc
    assert bounces > 0
    restitute(nc, ct, cidx, s.part_type, vx, vy, wz, sim.pt, mp, contact_arrays[7], prev)
    scaled = limit_energy(n, nc, s.part_type, sim.pt, (vx, vy, wz), v0, heat,
                          contact_arrays)
    assert scaled > 0      # the limit is exercised
    assert vx[:n] == pytest.approx(v[:, 0], abs=1e-12)
    assert vy[:n] == pytest.approx(v[:, 1], abs=1e-12)
    assert wz[:n] == pytest.approx(w, abs=1e-9)
    assert prev[:nc, PV_LN] == pytest.approx([i[0] for i in impulses], abs=1e-15)
    assert prev[:nc, PV_LT] == pytest.approx([i[1] for i in impulses], abs=1e-15)
    assert np.array_equal(prev[:nc, PV_KA], ct[:nc, CT_KA])


def test_sweep_limit_spends_the_work_budget():
    """Few contacts get sweeps up to the most, many the least; no budget: the least."""
    mp = np.zeros(MP_MAX_SWEEPS + 1)
    mp[MP_SWEEP_WORK] = 100_000
    mp[MP_MAX_SWEEPS] = 256
    assert [sweep_limit(nc, 16, mp) for nc in (0, 1, 100, 390, 391, 1000, 6250, 6251, 50_000)] \
        == [16, 256, 256, 256, 255, 100, 16, 16, 16]
    mp[MP_SWEEP_WORK] = 0.0
    assert sweep_limit(100, 16, mp) == 16


def test_the_cell_sets_the_sweep_budget_and_arguments_override_it():
    cell = make_cell(part_types=(disc(),))
    sim = MicroSim(cell, seed=0)
    assert (sim.mp[MP_SWEEP_WORK], sim.mp[MP_TOLERANCE]) == (200_000, 3e-4)
    cell = dataclasses.replace(cell, micro=dataclasses.replace(
        cell.micro, contact_sweeps=8, contact_sweeps_max=64, contact_sweep_budget=5000,
        contact_tolerance=5e-4))
    sim = MicroSim(cell, seed=0)
    assert (sim.cfg[CF_PASSES], sim.mp[MP_MAX_SWEEPS], sim.mp[MP_SWEEP_WORK],
            sim.mp[MP_TOLERANCE]) == (8, 64, 5000, 5e-4)
    sim = MicroSim(cell, seed=0, passes=3, max_passes=4, sweep_work=0, tolerance=0.0)
    assert (sim.cfg[CF_PASSES], sim.mp[MP_MAX_SWEEPS], sim.mp[MP_SWEEP_WORK],
            sim.mp[MP_TOLERANCE]) == (3, 4, 0, 0.0)
