"""Friction over the footprint couples sliding and spinning (Farkas et al., PRL 2003)."""

import math

import numpy as np
import pytest

from conveyor_twin.micro import MicroSim
from conveyor_twin.micro.footprint import (footprint_factors, footprint_table, FT_FORCE,
                                           FT_TORQUE)
from test.micro.conftest import box, disc, make_cell

G = 9.81


def quadrature(eps, n=600):
    """Return (f, t) of a unit disc slipping at 1 and spinning at eps, by brute force.

    Midpoint rule in polar coordinates over the footprint: the friction of every area element
    opposes its own velocity relative to the surface.
    """
    r = (np.arange(n) + 0.5) / n
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2.0 * np.pi
    rr, pp = np.meshgrid(r, phi)
    x = rr * np.cos(pp)
    y = rr * np.sin(pp)
    area = rr * (1.0 / n) * (np.pi / n)
    ux = 1.0 - eps * y
    uy = eps * x
    speed = np.hypot(ux, uy)
    force = np.sum(ux / speed * area) / np.pi
    torque = np.sum((x * uy - y * ux) / speed * area) / np.pi
    return force, torque


def test_table_matches_the_footprint_integral():
    ft = footprint_table()
    worst_f = worst_t = 0.0
    for q in np.linspace(0.0, 1.0, 41):
        if q == 1.0:
            f_exact, t_exact = 0.0, 2.0 / 3.0          # pure spin: mean distance 2a/3
        else:
            f_exact, t_exact = quadrature(q / (1.0 - q))
        f, t = footprint_factors(ft, 1.0 - q, q)        # slip speed, a |w|
        worst_f = max(worst_f, abs(f - f_exact))
        worst_t = max(worst_t, abs(t - t_exact))
    assert worst_f < 1e-4 and worst_t < 1e-4, (worst_f, worst_t)
    # the limits are exact: pure sliding, pure spinning
    assert footprint_factors(ft, 0.7, 0.0) == (1.0, 0.0)
    assert footprint_factors(ft, 0.0, 0.7) == (0.0, 2.0 / 3.0)
    # at eps = 1 the force is 8 / (3 pi) of the sliding force (the centre of rotation on the rim)
    assert footprint_factors(ft, 0.5, 0.5)[0] == pytest.approx(8.0 / (3.0 * np.pi), abs=1e-6)


def test_table_is_monotonic():
    ft = footprint_table()
    assert np.all(np.diff(ft[:, FT_FORCE]) < 0.0)
    assert np.all(np.diff(ft[:, FT_TORQUE]) > 0.0)


def reference_stop(v0, w0, a, mu, dt=2e-6):
    """Stopping time [s] of a disc (I = m a^2 / 2) under the exact law, integrated finely."""
    ft = footprint_table(2049)
    q = np.linspace(0.0, 1.0, ft.shape[0])
    v, w, t = v0, w0, 0.0
    while v > 0.0 or w > 0.0:
        e = a * w / (v + a * w)
        dv = mu * G * np.interp(e, q, ft[:, FT_FORCE]) * dt
        dw = mu * G * 2.0 / a * np.interp(e, q, ft[:, FT_TORQUE]) * dt
        if dv >= v and dw >= w:
            # both near zero: finish the last fraction of the step
            return t + dt * max(v / dv if dv else 0.0, w / dw if dw else 0.0)
        v = max(v - dv, 0.0)
        w = max(w - dw, 0.0)
        t += dt
    return t


def stop_steps(sim):
    """Step until the part neither slides nor spins; return the steps at which each stopped."""
    v_stop = w_stop = None
    steps = 0
    while v_stop is None or w_stop is None:
        sim.step(1)
        steps += 1
        p = sim.parts_view()
        if v_stop is None and p.vx[0] == 0.0 and p.vy[0] == 0.0:
            v_stop = steps
        if w_stop is None and p.wz[0] == 0.0:
            w_stop = steps
        assert steps < 100_000
    return v_stop, w_stop


@pytest.mark.parametrize('eps0', [0.5, 1.0, 3.0])
def test_sliding_and_spinning_stop_together(eps0):
    mu = 0.3
    part = disc(radius=0.02, mass=0.05)
    cell = make_cell(speed=0.0, friction=mu, part_types=[part])
    sim = MicroSim(cell, seed=0)
    v0 = 0.6
    w0 = eps0 * v0 / part.radius
    sim.spawn(0, 0.2, 0.0, 0.0, vx=v0, wz=w0)
    dt = cell.settings.step
    v_stop, w_stop = stop_steps(sim)
    # the PRL result: both motions end at the same moment
    assert abs(v_stop - w_stop) <= 2, (v_stop, w_stop)
    expected = reference_stop(v0, w0, part.radius, mu)
    assert max(v_stop, w_stop) * dt == pytest.approx(expected, rel=0.01)
    # and later than either motion alone: the force and the torque are both below their
    # uncoupled values (the uncoupled law stopped such a part early)
    assert expected > v0 / (mu * G)
    assert expected > w0 * part.inertia / (mu * part.mass * G * 2.0 * part.radius / 3.0)
    # the part slid straight: the force opposes the slip
    assert sim.parts_view().y[0] == 0.0


def test_box_spin_stops_under_the_footprint_torque():
    # a box's equivalent footprint has the box's own pure-spin torque mu m g * (mean distance)
    part = box(length=0.04, width=0.02)
    cell = make_cell(speed=0.0, friction=0.3, part_types=[part])
    sim = MicroSim(cell, seed=0)
    w0 = 15.0
    sim.spawn(0, 0.2, 0.0, 0.0, wz=w0)
    k = 400
    u = (np.arange(k) + 0.5) / k - 0.5
    gx, gy = np.meshgrid(u * part.length, u * part.width)
    arm = float(np.mean(np.hypot(gx, gy)))
    expected = w0 * part.inertia / (0.3 * part.mass * G * arm)
    _, w_stop = stop_steps(sim)
    assert w_stop * cell.settings.step == pytest.approx(expected, abs=cell.settings.step)
    assert math.isclose(sim.parts_view().x[0], 0.2)
