"""Observed order of convergence on a smooth advection problem (analytic cell averages)."""

import math

import numpy as np
import pytest

from conveyor_twin.macro import MacroSim
from conveyor_twin.macro.fluxes import LIMITER_MC, LIMITER_MINMOD
from .cells import belt, make_cell

SIGMA = 0.05          # m, Gaussian width
X0, Y0 = 0.2, 0.2     # m, initial centre
SPEED = 0.5           # m/s along (0.8, 0.6)
T_END = 0.4           # s
PEAK = 1000.0         # parts/m^2, far below rho_max: the cap never acts


def _cell_averages(sim, xc, yc):
    erf = np.vectorize(math.erf)
    h = sim.resolution
    xe = sim.origin_x + np.arange(sim.nx + 1) * h
    ye = sim.origin_y + np.arange(sim.ny + 1) * h
    s = SIGMA * math.sqrt(2.0)
    fx = np.diff(erf((xe - xc) / s)) * (SIGMA * math.sqrt(math.pi / 2.0)) / h
    fy = np.diff(erf((ye - yc) / s)) * (SIGMA * math.sqrt(math.pi / 2.0)) / h
    return PEAK * np.outer(fy, fx)


def _error(scheme, h, limiter):
    cell = make_cell(region=(0.0, 0.0, 0.6, 0.6), resolution=h, step=h,  # c = 0.4 and 0.3
                     belts=[belt((-0.5, -0.375), (1.1, 0.825), 3.0, SPEED)],
                     scheme=scheme, rho_max=1e9, cfl=1.0)
    sim = MacroSim(cell, limiter=limiter)
    sim.density[:] = _cell_averages(sim, X0, Y0)
    steps = int(round(T_END / h))
    sim.step(steps)
    exact = _cell_averages(sim, X0 + 0.8 * SPEED * T_END, Y0 + 0.6 * SPEED * T_END)
    return np.abs(sim.density - exact).sum() * h * h      # L1 [parts]


@pytest.mark.parametrize('scheme,limiter,low,high', [
    ('upwind', LIMITER_MC, 0.8, 1.2),
    ('limited', LIMITER_MC, 1.8, 2.3),
    ('limited', LIMITER_MINMOD, 1.5, 2.3),
])
def test_observed_order(scheme, limiter, low, high):
    errors = [_error(scheme, h, limiter) for h in (0.01, 0.005, 0.0025)]
    orders = [math.log2(errors[k] / errors[k + 1]) for k in range(2)]
    assert low <= orders[-1] <= high, (errors, orders)
    assert errors[-1] < errors[0]
