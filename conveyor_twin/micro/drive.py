"""Belts: speed ramps and the friction drive of the parts standing on them.

A part is on the first belt (cell order) whose surface rectangle holds its centre. Its velocity
relaxes toward the belt surface velocity by at most ``mu g dt`` per substep (Coulomb friction
bounded by ``mu m g``), so a part starting ``dv`` off the belt speed reaches it after
``dv / (mu g)``. Spinning parts feel the matching torque ``mu m g a`` (``a`` the mean distance of
the footprint from its centre, uniform pressure), which stops the spin relative to the belt.
Parts off every belt stand on a floor with friction :data:`FLOOR_FRICTION`.
"""

import math
from typing import Sequence

from numba import njit
import numpy as np

from conveyor_twin.cell.model import Belt
from conveyor_twin.micro.contacts.tables import A_BELT, MP_DT, MP_FLOOR_MU, MP_GRAVITY, MP_TRACK
from conveyor_twin.micro.state import PT_INV_INERTIA, PT_MASS, PT_SPIN_ARM

# Friction coefficient between a part and the fixed floor beside the belts.
FLOOR_FRICTION = 0.3

# --- belt table columns ---
BT_SX = 0
BT_SY = 1
BT_DX = 2
BT_DY = 3
BT_LENGTH = 4
BT_HALF_WIDTH = 5
BT_MU = 6
BT_DV = 7             # largest speed change per step [m/s]
BT_COLUMNS = 8


def belt_table(belts: Sequence[Belt], dt: float) -> np.ndarray:
    """Return the (B, BT_COLUMNS) table of the belts for step ``dt`` [s]."""
    table = np.zeros((len(belts), BT_COLUMNS), dtype=np.float64)
    for i, b in enumerate(belts):
        d = b.direction
        table[i] = (b.start[0], b.start[1], d[0], d[1], b.length, 0.5 * b.width, b.friction,
                    b.acceleration * dt)
    return table


@njit(cache=True)
def ramp(value, target, limit):
    """Move ``value`` toward ``target`` by at most ``limit`` in place, landing on it exactly.

    The coordinator ramps belts and actuators with this same kernel.
    """
    for i in range(value.size):
        diff = target[i] - value[i]
        if abs(diff) <= limit[i]:
            value[i] = target[i]
        elif diff > 0.0:
            value[i] += limit[i]
        else:
            value[i] -= limit[i]


@njit(cache=True, inline='always')
def belt_under(belts, px, py):
    """Return the index of the first belt whose surface holds the point p [m], or -1."""
    for b in range(belts.shape[0]):
        rx = px - belts[b, BT_SX]
        ry = py - belts[b, BT_SY]
        dx = belts[b, BT_DX]
        dy = belts[b, BT_DY]
        u = rx * dx + ry * dy
        w = ry * dx - rx * dy
        if 0.0 <= u <= belts[b, BT_LENGTH] and abs(w) <= belts[b, BT_HALF_WIDTH]:
            return b
    return -1


@njit(cache=True)
def surface_velocity(belts, speed, px, py, floor_mu):
    """Return (v_x, v_y, mu) of the surface under the point p [m]: a belt's or the floor's."""
    b = belt_under(belts, px, py)
    if b >= 0:
        return speed[b] * belts[b, BT_DX], speed[b] * belts[b, BT_DY], belts[b, BT_MU]
    return 0.0, 0.0, floor_mu


@njit(cache=True)
def belt_drive(n, ptype, x, y, vx, vy, wz, pt, belts, speed, mp, acc, heat):
    """Apply one substep of surface friction to parts 0..n-1 (velocities in place).

    :param speed: float64[B] actual belt speeds [m/s]. :param mp: model parameters.
    :param acc: activities; the belt's gets ``|F . slip| dt`` when tracking.
    :param heat: float64[capacity] (output): the energy each part's surface friction dissipated
        in the substep [J], ``J . (u - v) - |J|^2 / (2 m)`` for the friction impulse ``J``, the
        surface velocity ``u`` and the part's velocity ``v`` before it (and the same for the
        spin): the work the surface did on the part less its gain of kinetic energy, >= 0.
    """
    g_dt = mp[MP_GRAVITY] * mp[MP_DT]
    floor_mu = mp[MP_FLOOR_MU]
    track = mp[MP_TRACK] != 0.0
    for i in range(n):
        t = ptype[i]
        b = belt_under(belts, x[i], y[i])
        if b >= 0:
            bvx = speed[b] * belts[b, BT_DX]
            bvy = speed[b] * belts[b, BT_DY]
            mu = belts[b, BT_MU]
        else:
            bvx = 0.0
            bvy = 0.0
            mu = floor_mu
        dvx = bvx - vx[i]
        dvy = bvy - vy[i]
        d = math.sqrt(dvx * dvx + dvy * dvy)
        limit = mu * g_dt
        if d <= limit:
            vx[i] = bvx
            vy[i] = bvy
            # slip falls from d to 0: mean slip d / 2 under the impulse m d
            q = 0.5 * pt[t, PT_MASS] * d * d
        else:
            f = limit / d
            vx[i] += dvx * f
            vy[i] += dvy * f
            q = pt[t, PT_MASS] * limit * (d - 0.5 * limit)
        w_limit = limit * pt[t, PT_MASS] * pt[t, PT_SPIN_ARM] * pt[t, PT_INV_INERTIA]
        w = wz[i]
        if abs(w) <= w_limit:
            wz[i] = 0.0
            q += 0.5 * w * w / pt[t, PT_INV_INERTIA]
        else:
            wz[i] = w - w_limit if w > 0.0 else w + w_limit
            q += (w_limit / pt[t, PT_INV_INERTIA]) * (abs(w) - 0.5 * w_limit)
        heat[i] = q
        if track:
            acc[A_BELT] += q
