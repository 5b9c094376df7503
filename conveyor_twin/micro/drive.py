"""Belts: speed ramps and the friction drive of the parts standing on them.

A part stands on the surface under its centre
(:func:`~conveyor_twin.micro.surfaces.surface_under`: an engaged transfer unit, else the first
belt in cell order holding it, straight or curved, else the floor), which moves at a velocity
and, on a curve, a spin of its own. Coulomb friction over its footprint
(:mod:`conveyor_twin.micro.footprint`) pulls its slip ``v`` (its velocity less the surface's)
and its spin ``w`` relative to the surface toward zero: per substep ``h`` the slip falls by ``mu
g h f`` and the spin by ``mu g h (m a / I) t``, with ``f`` and ``t`` the footprint's force and
torque factors at ``eps = a |w| / |v|`` (``a`` the footprint radius), each landing exactly on
zero when the step would take it past (no overshoot, so no energy gain). Pure sliding (``f =
1``): a part ``dv`` off the belt speed reaches it after ``dv / (mu g)``; pure spinning (``t =
2/3``): the torque ``mu m g (2 a / 3)``. Sliding and spinning together stop together, later than
either would alone. A part sticking to a curve takes its chord velocity over the substep and its
spin, so it stays on its arc. The floor's friction is :data:`FLOOR_FRICTION`.
"""

import math

from numba import njit

from conveyor_twin.micro.contacts.tables import A_BELT, MP_DT, MP_FLOOR_MU, MP_GRAVITY, MP_TRACK
from conveyor_twin.micro.footprint import footprint_factors, RADIUS_PER_SPIN_ARM
from conveyor_twin.micro.surfaces import (all_straight, belt_surface, prepare_rotations,
                                          straight_belt_surface, surface_under)
from conveyor_twin.micro.state import PT_INV_INERTIA, PT_MASS, PT_SPIN_ARM

# Friction coefficient between a part and the fixed floor beside the belts.
FLOOR_FRICTION = 0.3


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


@njit(cache=True)
def surface_velocity(surfaces, speed, px, py, floor_mu):
    """Return (v_x, v_y, spin, mu) of the surface under the point p [m] (velocities [m/s], spin
    [rad/s]): an engaged transfer unit's, a belt's or the floor's; on a curve the instantaneous
    velocity (:func:`~conveyor_twin.micro.surfaces.surface_under` with ``h = 0``).

    :param surfaces: as for :func:`belt_drive`; ``speed`` the belts' speeds [m/s].
    """
    return surface_under(surfaces, speed, px, py, floor_mu, 0.0)


# No reference counting in the loop (``_nrt=False``: the kernel allocates nothing); numba keeps
# incref/decref pairs of the arrays its inlined lookups read, which cost more than the lookups.
@njit(cache=True, _nrt=False)
def belt_drive(n, ptype, x, y, vx, vy, wz, pt, surfaces, speed, mp, acc, heat):
    """Apply one substep of surface friction to parts 0..n-1 (velocities in place).

    :param surfaces: ``(belts, transfers, transfer_position, footprint)``: the belt table, the
        transfer units' table and their lift at the substep [m], the footprint table
        (:func:`~conveyor_twin.micro.footprint.footprint_table`).
    :param speed: float64[B] actual belt speeds [m/s]. :param mp: model parameters.
    :param acc: activities; the belt's gets ``|F . slip| dt`` when tracking.
    :param heat: float64[capacity] (output): the energy each part's surface friction dissipated
        in the substep [J], ``J . (u - v) - |J|^2 / (2 m)`` for the friction impulse ``J``, the
        surface velocity ``u`` and the part's velocity ``v`` before it, and the same for the spin
        relative to the surface's: the work the surface did on the part less its gain of kinetic
        energy, >= 0.
    """
    belts = surfaces[0]
    plain = surfaces[1].shape[0] == 0                   # no transfer units
    straight = plain and all_straight(belts)            # nor curved belts
    ft = surfaces[3]
    h = mp[MP_DT]
    if not straight:
        prepare_rotations(belts, speed, h)
    g_dt = mp[MP_GRAVITY] * h
    floor_mu = mp[MP_FLOOR_MU]
    track = mp[MP_TRACK] != 0.0
    for i in range(n):
        t = ptype[i]
        if straight:
            bvx, bvy, bw, mu = straight_belt_surface(belts, speed, x[i], y[i], floor_mu)
        elif plain:
            bvx, bvy, bw, mu = belt_surface(belts, speed, x[i], y[i], floor_mu, h)
        else:
            bvx, bvy, bw, mu = surface_under(surfaces, speed, x[i], y[i], floor_mu, h)
        dvx = bvx - vx[i]
        dvy = bvy - vy[i]
        d = math.sqrt(dvx * dvx + dvy * dvy)
        w = wz[i] - bw
        arm = RADIUS_PER_SPIN_ARM * pt[t, PT_SPIN_ARM]
        cf, ct = footprint_factors(ft, d, arm * abs(w))
        limit = mu * g_dt
        v_limit = limit * cf
        if d <= v_limit:
            vx[i] = bvx
            vy[i] = bvy
            # slip falls from d to 0: mean slip d / 2 under the impulse m d
            q = 0.5 * pt[t, PT_MASS] * d * d
        else:
            f = v_limit / d
            vx[i] += dvx * f
            vy[i] += dvy * f
            q = pt[t, PT_MASS] * v_limit * (d - 0.5 * v_limit)
        w_limit = limit * ct * pt[t, PT_MASS] * arm * pt[t, PT_INV_INERTIA]
        if abs(w) <= w_limit:
            wz[i] = bw
            q += 0.5 * w * w / pt[t, PT_INV_INERTIA]
        else:
            wz[i] = bw + (w - w_limit if w > 0.0 else w + w_limit)
            q += (w_limit / pt[t, PT_INV_INERTIA]) * (abs(w) - 0.5 * w_limit)
        heat[i] = q
        if track:
            acc[A_BELT] += q
