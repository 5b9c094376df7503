"""Coulomb friction over a part's footprint, coupling sliding and spinning.

A part slipping at ``v`` (its velocity less the surface's, at its centre) while spinning at ``w``
relative to the surface feels, summed over a uniformly loaded disc footprint of radius ``a``,
the force ``mu N f(eps)`` against the slip and the torque ``mu N a t(eps)`` against the spin,
``eps = a |w| / |v|`` (Farkas, Bartels, Unger and Wolf, "Frictional coupling between sliding
and spinning motion", PRL 90, 248302, 2003). Pure sliding: ``f = 1, t = 0``; pure spinning:
``f = 0, t = 2/3``; in between both are smaller than their uncoupled values, so a part that
slides and spins keeps each motion longer than it would alone, and both motions stop together
(damping them separately, with the full force and torque, stops such a part up to ~25 % early).

The exact law, with ``Phi(s)`` the integral of the distance to the point at ``s a`` from the
centre over the unit disc (``s = 1 / eps``: the instantaneous centre of rotation of the slip)::

    f = Phi'(s) / pi,    t = (Phi(s) - s Phi'(s)) / pi

``Phi`` and ``Phi'`` are one-dimensional integrals of complete elliptic integrals, evaluated once
(Gauss-Legendre, error < 1e-8) into a table over ``q = a|w| / (|v| + a|w|)`` in [0, 1] (``q = 0``
pure sliding, ``q = 1`` pure spinning) that the kernels interpolate linearly (error < 3e-5).
Boxes use the disc of the same pure-spin torque: ``a = 1.5 * spin_arm`` (``spin_arm`` the mean
distance of the footprint from the centre, :func:`conveyor_twin.micro.state.spin_arm`).
"""

import functools
import math

from numba import njit
import numpy as np

# Rows of the footprint table; its columns:
FT_FORCE = 0          # f(q): force / (mu N)
FT_TORQUE = 1         # t(q): torque / (mu N a)
FT_COLUMNS = 2
FOOTPRINT_POINTS = 513
# Footprint radius of the equivalent disc per mean distance of the footprint from its centre.
RADIUS_PER_SPIN_ARM = 1.5
_NODES = 64


def _elliptic_k_e(m: np.ndarray) -> tuple:
    """Return the complete elliptic integrals K(m), E(m) (parameter ``m = k^2`` < 1), by AGM."""
    a = np.ones_like(m)
    b = np.sqrt(1.0 - m)
    total = 0.5 * m
    power = 0.5
    for _ in range(60):
        c = 0.5 * (a - b)
        a, b = 0.5 * (a + b), np.sqrt(a * b)
        power *= 2.0
        total = total + power * c * c
        if np.all(np.abs(c) <= 1e-17 * a):
            break
    k = 0.5 * np.pi / a
    return k, k * (1.0 - total)


def _phi(s: float) -> tuple:
    """Return (Phi(s), Phi'(s)) of the unit disc for the point at distance ``s`` > 0."""
    x, w = np.polynomial.legendre.leggauss(_NODES)
    phi = 0.0
    dphi = 0.0
    for lo, hi in ((0.0, s), (s, 1.0)) if s < 1.0 else ((0.0, 1.0),):
        r = lo + 0.5 * (hi - lo) * (x + 1.0)
        ww = 0.5 * (hi - lo) * w
        k, e = _elliptic_k_e(4.0 * r * s / (r + s) ** 2)
        # the integral over the angle of |r - s| is 4 (r + s) E(m); its derivative by s:
        phi += float(np.sum(ww * r * 4.0 * (r + s) * e))
        dphi += float(np.sum(ww * r * (4.0 * e + 2.0 * (r - s) * (e - k) / s)))
    return phi, dphi


@functools.lru_cache(maxsize=None)
def _table(points: int) -> np.ndarray:
    table = np.zeros((points, FT_COLUMNS))
    table[0] = (1.0, 0.0)
    table[-1] = (0.0, 2.0 / 3.0)
    for i in range(1, points - 1):
        q = i / (points - 1)
        s = (1.0 - q) / q
        phi, dphi = _phi(s)
        table[i] = (dphi / math.pi, (phi - s * dphi) / math.pi)
    table.setflags(write=False)
    return table


def footprint_table(points: int = FOOTPRINT_POINTS) -> np.ndarray:
    """Return the (points, FT_COLUMNS) table of f and t at ``q = i / (points - 1)`` (a copy)."""
    if points < 2:
        raise ValueError(f'footprint table: points = {points}, expected >= 2')
    return _table(int(points)).copy()


@njit(cache=True, inline='always')
def footprint_factors(ft, slip, spin):
    """Return (f, t) for the slip speed ``slip`` >= 0 [m/s] and ``spin = a |w|`` >= 0 [m/s].

    ``ft``: the table of :func:`footprint_table`. Without spin: pure sliding's (1, 0), also
    when neither moves.
    """
    if spin <= 0.0:
        return 1.0, 0.0                                 # pure sliding (or neither)
    total = slip + spin
    x = spin / total * (ft.shape[0] - 1)
    i = int(x)
    if i >= ft.shape[0] - 1:
        i = ft.shape[0] - 2
    u = x - i
    f = ft[i, FT_FORCE] + u * (ft[i + 1, FT_FORCE] - ft[i, FT_FORCE])
    t = ft[i, FT_TORQUE] + u * (ft[i + 1, FT_TORQUE] - ft[i, FT_TORQUE])
    return f, t
