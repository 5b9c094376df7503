"""Plain NumPy reference of the macro step, written for reading, not speed.

It implements the same discretisation as the numba kernels (see :mod:`.fluxes`,
:mod:`.collision`, :mod:`.solver`) with whole-array operations, and is what the tests compare
the kernels against. :func:`upwind_step` is the bare NumPy split upwind step the benchmark
uses as its baseline.
"""

from typing import Tuple

import numpy as np

from conveyor_twin.macro.collision import H_TOLERANCE
from conveyor_twin.macro.fluxes import LIMITER_MC, LIMITER_MINMOD


def limited_slope(dl: np.ndarray, dr: np.ndarray, limiter: int) -> np.ndarray:
    """Return limited differences (minmod, MC or van Leer) elementwise [parts/m^2]."""
    adl, adr = np.abs(dl), np.abs(dr)
    if limiter == LIMITER_MINMOD:
        m = np.minimum(adl, adr)
    elif limiter == LIMITER_MC:
        m = np.minimum(np.minimum(2.0 * adl, 2.0 * adr), 0.5 * (adl + adr))
    else:
        total = adl + adr
        m = np.where(total > 0.0, 2.0 * adl * adr / np.where(total > 0.0, total, 1.0), 0.0)
    return np.where(dl * dr > 0.0, np.copysign(m, dl), 0.0)


def _sweep_lines(rho: np.ndarray, w: np.ndarray, solid: np.ndarray, k: float,
                 rho_max: float, capped: bool, limited: bool, limiter: int,
                 in_lo: np.ndarray, in_hi: np.ndarray, in_scale: float) -> np.ndarray:
    """Return the face amounts of one sweep along axis 1 (lines = rows of the arguments).

    :param rho: ``(m, n)``; :param w: ``(m, n + 1)`` face velocities; :param solid: ``(m, n)``.
    :param in_lo: inflow rates [parts/s] at face 0 of each line; :param in_hi: at face n.
    """
    m, n = rho.shape
    a = np.zeros((m, n + 1))
    c = w * k
    fluid = solid == 0
    # Boundary faces.
    a[:, 0] = np.where(w[:, 0] < 0.0, c[:, 0] * rho[:, 0],
                       np.where(fluid[:, 0], in_lo * in_scale, 0.0))
    a[:, n] = np.where(w[:, n] > 0.0, c[:, n] * rho[:, n - 1],
                       np.where(fluid[:, n - 1], -in_hi * in_scale, 0.0))
    slope = np.zeros((m, n))
    if limited and n > 2:
        ok = fluid[:, :-2] & fluid[:, 2:]
        s = limited_slope(rho[:, 1:-1] - rho[:, :-2], rho[:, 2:] - rho[:, 1:-1], limiter)
        slope[:, 1:-1] = np.where(ok, s, 0.0)
    ci = c[:, 1:n]
    left = rho[:, :-1]
    right = rho[:, 1:]
    if limited:
        left = left + 0.5 * (1.0 - ci) * slope[:, :-1]
        right = right - 0.5 * (1.0 + ci) * slope[:, 1:]
    a[:, 1:n] = np.where(ci > 0.0, ci * left, np.where(ci < 0.0, ci * right, 0.0))
    if limited:
        out = np.maximum(a[:, 1:], 0.0) - np.minimum(a[:, :-1], 0.0)
        scale = np.where(out > rho, rho / np.where(out > 0.0, out, 1.0), 1.0)
        a[:, 1:] = np.where(a[:, 1:] > 0.0, a[:, 1:] * scale, a[:, 1:])
        a[:, :-1] = np.where(a[:, :-1] < 0.0, a[:, :-1] * scale, a[:, :-1])
    if capped:
        # Positive faces, downstream first; receiver is cell f.
        for f in range(n - 1, -1, -1):
            af, ar = a[:, f], a[:, f + 1]
            pos = af > 0.0
            conv = pos & (ar < 0.0)
            cap_c = np.maximum(rho_max - rho[:, f], 0.0)
            total = af - ar
            s = np.where(conv & (total > cap_c), cap_c / np.where(total > 0.0, total, 1.0), 1.0)
            cap_o = np.maximum(rho_max - rho[:, f] + ar, 0.0)
            new_f = np.where(conv, af * s, np.where(pos & (af > cap_o), cap_o, af))
            a[:, f + 1] = np.where(conv, ar * s, ar)
            a[:, f] = new_f
        # Negative faces, downstream first; receiver is cell f - 1.
        for f in range(1, n + 1):
            af, al = a[:, f], a[:, f - 1]
            neg = (af < 0.0) & ~(al > 0.0)
            cap = np.maximum(rho_max - rho[:, f - 1] - al, 0.0)
            a[:, f] = np.where(neg & (-af > cap), -cap, af)
    return a


def sweep(rho: np.ndarray, w: np.ndarray, solid: np.ndarray, axis: int, dts: float, h: float,
          rho_max: float, capped: bool, limited: bool, limiter: int, in_rate: np.ndarray,
          in_acc: np.ndarray, out_acc: np.ndarray) -> None:
    """Advance ``rho`` in place by one sweep along ``axis`` (1: x, 0: y); see ``fluxes``."""
    ny, nx = rho.shape
    area = h * h
    if axis == 1:
        lo, hi = in_rate[:ny], in_rate[ny:2 * ny]
        a = _sweep_lines(rho, w, solid, dts / h, rho_max, capped, limited, limiter, lo, hi,
                         dts / area)
        rho += a[:, :-1] - a[:, 1:]
        sl_lo, sl_hi = slice(0, ny), slice(ny, 2 * ny)
    else:
        lo, hi = in_rate[2 * ny:2 * ny + nx], in_rate[2 * ny + nx:]
        a = _sweep_lines(rho.T, w.T, solid.T, dts / h, rho_max, capped, limited, limiter, lo,
                         hi, dts / area)
        rho += (a[:, :-1] - a[:, 1:]).T
        sl_lo, sl_hi = slice(2 * ny, 2 * ny + nx), slice(2 * ny + nx, 2 * (nx + ny))
    a0, an = a[:, 0], a[:, -1]
    in_acc[sl_lo] += np.where(a0 > 0.0, a0 * area, 0.0)
    out_acc[sl_lo] += np.where(a0 > 0.0, 0.0, -a0 * area)
    out_acc[sl_hi] += np.where(an > 0.0, an * area, 0.0)
    in_acc[sl_hi] += np.where(an > 0.0, 0.0, -an * area)


def _conv(field: np.ndarray, w: np.ndarray, axis: int) -> np.ndarray:
    """Return the zero-padded convolution of ``field`` with the taps ``w`` along ``axis``."""
    r = (w.size - 1) // 2
    moved = np.moveaxis(field, axis, 0)
    n = moved.shape[0]
    pad = np.zeros((n + 2 * r,) + moved.shape[1:])
    pad[r:r + n] = moved
    out = sum(w[k] * pad[k:k + n] for k in range(w.size))
    return np.moveaxis(out, 0, axis)


def collision_velocity(rho: np.ndarray, solid: np.ndarray, rho_max: float, eps: float,
                       h: float, w: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return the operator face velocities ``(Ix, Iy)`` [m/s] on the whole grid.

    ``grad(eta * rho)`` as ``eta * grad(rho)`` with zero differences across solid faces and
    outside the grid; a face pushes only down its own density difference (see ``collision``).
    """
    ny, nx = rho.shape
    fluid = solid == 0
    full = rho >= rho_max * (1.0 - H_TOLERANCE)
    dx = np.zeros((ny, nx + 1))
    dy = np.zeros((ny + 1, nx))
    ok_x = fluid[:, :-1] & fluid[:, 1:]
    ok_y = fluid[:-1, :] & fluid[1:, :]
    dx[:, 1:nx] = np.where(ok_x, (rho[:, 1:] - rho[:, :-1]) * (1.0 / h), 0.0)
    dy[1:ny, :] = np.where(ok_y, (rho[1:, :] - rho[:-1, :]) * (1.0 / h), 0.0)
    gx = _conv(_conv(dx, w, 1), w, 0)
    gy = _conv(_conv(dy, w, 1), w, 0)
    ix = np.zeros((ny, nx + 1))
    iy = np.zeros((ny + 1, nx))
    tx = gx[:, 1:nx]
    ty = 0.25 * (((gy[:-1, :-1] + gy[:-1, 1:]) + gy[1:, :-1]) + gy[1:, 1:])
    act = ok_x & (full[:, :-1] | full[:, 1:]) & (tx * (rho[:, 1:] - rho[:, :-1]) > 0.0)
    ix[:, 1:nx] = np.where(act, -eps * tx / np.sqrt(1.0 + tx * tx + ty * ty), 0.0)
    ty = gy[1:ny, :]
    tx = 0.25 * (((gx[:-1, :-1] + gx[:-1, 1:]) + gx[1:, :-1]) + gx[1:, 1:])
    act = ok_y & (full[:-1, :] | full[1:, :]) & (ty * (rho[1:, :] - rho[:-1, :]) > 0.0)
    iy[1:ny, :] = np.where(act, -eps * ty / np.sqrt(1.0 + tx * tx + ty * ty), 0.0)
    return ix, iy


class ReferenceSim:
    """NumPy twin of a :class:`conveyor_twin.macro.solver.MacroSim` (same geometry and state).

    :param sim: the MacroSim whose velocity field, solids, parameters and density are copied.
    """

    def __init__(self, sim) -> None:
        self.rho = sim.density.copy()
        self.ux, self.uy = (u.copy() for u in sim.face_velocity)
        self.solid = sim.solid.copy()
        self.h = sim.resolution
        self.rho_max = sim.rho_max
        self.eps = sim.epsilon
        self.w = sim._w.copy()
        self.dt = sim.dt
        self.nsub = sim.substeps
        self.capped = sim.capacity_guard
        self.goettlich = sim.variant == 'goettlich'
        self.limited = sim.scheme == 'limited'
        self.limiter = sim.limiter
        self.parity = int(sim._parity[0])
        self.in_rate = sim._in_rate.copy()
        self.inflow = np.zeros_like(self.in_rate)
        self.outflow = np.zeros_like(self.in_rate)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` twin steps."""
        dts = self.dt / self.nsub
        self.inflow[:] = 0.0
        self.outflow[:] = 0.0
        for _ in range(n * self.nsub):
            wx, wy = self.ux, self.uy
            if self.goettlich:
                ix, iy = collision_velocity(self.rho, self.solid, self.rho_max, self.eps, self.h,
                                            self.w)
                wx, wy = self.ux + ix, self.uy + iy
            args = (dts, self.h, self.rho_max, self.capped, self.limited, self.limiter,
                    self.in_rate, self.inflow, self.outflow)
            order = (1, 0) if self.parity % 2 == 0 else (0, 1)
            for axis in order:
                sweep(self.rho, wx if axis == 1 else wy, self.solid, axis, *args)
            self.parity += 1


def upwind_step(rho: np.ndarray, ux: np.ndarray, uy: np.ndarray, k: float) -> None:
    """Advance ``rho`` by one plain split upwind step (no cap, no BC bookkeeping), in place.

    The benchmark's NumPy baseline: ``k = dt / h``; face velocities as in :mod:`.grid`.
    """
    a = ux * k
    fx = np.zeros_like(ux)
    fx[:, 1:-1] = np.where(a[:, 1:-1] > 0.0, a[:, 1:-1] * rho[:, :-1], a[:, 1:-1] * rho[:, 1:])
    fx[:, 0] = np.minimum(a[:, 0], 0.0) * rho[:, 0]
    fx[:, -1] = np.maximum(a[:, -1], 0.0) * rho[:, -1]
    rho += fx[:, :-1] - fx[:, 1:]
    b = uy * k
    fy = np.zeros_like(uy)
    fy[1:-1] = np.where(b[1:-1] > 0.0, b[1:-1] * rho[:-1], b[1:-1] * rho[1:])
    fy[0] = np.minimum(b[0], 0.0) * rho[0]
    fy[-1] = np.maximum(b[-1], 0.0) * rho[-1]
    rho += fy[:-1] - fy[1:]
