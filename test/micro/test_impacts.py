"""Disc-disc impacts against the closed-form post-impact velocities; invariants of impulses."""

import math

import numpy as np
import pytest

from conveyor_twin.micro import MicroSim
from conveyor_twin.micro.contacts import impulse_response
from test.micro.conftest import disc, make_cell


def closed_form(m1, m2, u1, u2, e):
    """Return the 1-D post-impact velocities of two bodies (Newton's restitution law)."""
    v1 = (m1 * u1 + m2 * u2 - m2 * e * (u1 - u2)) / (m1 + m2)
    v2 = (m1 * u1 + m2 * u2 + m1 * e * (u1 - u2)) / (m1 + m2)
    return v1, v2


@pytest.mark.parametrize('e', [0.0, 0.5, 1.0])
def test_head_on_simulated(e):
    m1, m2, r = 0.01, 0.03, 0.005
    light = disc(mass=m1, restitution=e)
    heavy = disc(mass=m2, restitution=e, name='heavy')
    cell = make_cell(part_types=(light, heavy), friction=0.0)
    sim = MicroSim(cell, seed=0)
    sim.spawn(0, 0.5, 0.0, 0.0, vx=1.0)
    sim.spawn(1, 0.53, 0.0, 0.0, vx=-0.5)
    sim.step(60)
    v = sim.parts_view()
    expect = closed_form(m1, m2, 1.0, -0.5, e)
    assert v.vx[0] == pytest.approx(expect[0], abs=1e-12)
    assert v.vx[1] == pytest.approx(expect[1], abs=1e-12)
    assert np.all(v.vy == 0.0) and np.all(v.wz == 0.0)
    assert v.x[1] - v.x[0] >= 2 * r - 1e-4 - 1e-12


@pytest.mark.parametrize('e', [0.0, 0.5, 1.0])
@pytest.mark.parametrize('mu', [0.0, 0.05, 0.8])
def test_oblique_disc_disc(e, mu):
    # disc A moving +x hits resting disc B; the line of centres at 30 degrees
    m, r = 0.01, 0.005
    inertia = 0.5 * m * r * r
    theta = math.radians(30.0)
    n = np.array([-math.cos(theta), -math.sin(theta)])   # from B to A
    t = np.array([-n[1], n[0]])
    u = np.array([1.0, 0.0])
    ra = -r * n
    rb = r * n
    out = impulse_response((u[0], u[1], 0.0, 1 / m, 1 / inertia, ra[0], ra[1]),
                           (0.0, 0.0, 0.0, 1 / m, 1 / inertia, rb[0], rb[1]), n[0], n[1], e,
                           (mu, mu, 0.01))
    va, wa, vb, wb = np.array(out[:2]), out[2], np.array(out[3:5]), out[5]
    un = u @ n
    ut = u @ t
    jn = -(1 + e) * un / (2 / m)
    # tangential: stick needs j_t = -u_t / k_t with k_t = 2/m + 2 r^2 / I (= 6/m for discs)
    kt = 2 / m + 2 * r * r / inertia
    jt = float(np.clip(-ut / kt, -mu * jn, mu * jn))
    expect_va = u + (jn * n + jt * t) / m
    expect_vb = -(jn * n + jt * t) / m
    expect_wa = (ra[0] * t[1] - ra[1] * t[0]) * jt / inertia
    expect_wb = -(rb[0] * t[1] - rb[1] * t[0]) * jt / inertia
    assert va == pytest.approx(expect_va, abs=1e-12)
    assert vb == pytest.approx(expect_vb, abs=1e-12)
    assert wa == pytest.approx(expect_wa, abs=1e-9)
    assert wb == pytest.approx(expect_wb, abs=1e-9)
    # the normal part alone is the 1-D law
    assert (va - vb) @ n == pytest.approx(-e * un, abs=1e-12)
    if mu == 0.0:
        assert va @ t == pytest.approx(ut, abs=1e-12)


def test_random_impacts_conserve_momentum_and_never_gain_energy():
    rng = np.random.default_rng(42)
    for _ in range(10_000):
        ma, mb = rng.uniform(0.001, 1.0, 2)
        ia, ib = rng.uniform(1e-8, 1e-3, 2)
        va, vb = rng.normal(size=2), rng.normal(size=2)
        wa, wb = rng.normal(scale=10.0, size=2)
        ra, rb = rng.normal(scale=0.02, size=2), rng.normal(scale=0.02, size=2)
        phi = rng.uniform(0, 2 * math.pi)
        n = np.array([math.cos(phi), math.sin(phi)])
        e = rng.uniform(0, 1)
        mu_s, mu_k = rng.uniform(0, 1.0, 2)
        out = impulse_response((va[0], va[1], wa, 1 / ma, 1 / ia, ra[0], ra[1]),
                               (vb[0], vb[1], wb, 1 / mb, 1 / ib, rb[0], rb[1]), n[0], n[1], e,
                               (mu_s, mu_k, 0.05))
        va2, wa2, vb2, wb2 = np.array(out[:2]), out[2], np.array(out[3:5]), out[5]
        p0 = ma * va + mb * vb
        p1 = ma * va2 + mb * vb2
        assert p1 == pytest.approx(p0, abs=1e-9 * (1 + np.abs(p0).max()))

        def cross(r, v):
            return r[0] * v[1] - r[1] * v[0]

        # angular momentum about the contact point
        c = np.zeros(2)
        l0 = ia * wa + ib * wb + cross(-ra, ma * va) + cross(-rb, mb * vb) + cross(c, p0)
        l1 = ia * wa2 + ib * wb2 + cross(-ra, ma * va2) + cross(-rb, mb * vb2)
        assert l1 == pytest.approx(l0, abs=1e-9 * (1 + abs(l0)))
        ke0 = 0.5 * (ma * va @ va + mb * vb @ vb + ia * wa * wa + ib * wb * wb)
        ke1 = 0.5 * (ma * va2 @ va2 + mb * vb2 @ vb2 + ia * wa2 * wa2 + ib * wb2 * wb2)
        assert ke1 <= ke0 * (1 + 1e-12) + 1e-15
