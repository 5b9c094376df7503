"""The surface under a point: transfer units, straight and curved belts, the floor.

``surface_under`` answers, for a point, the velocity and spin of the surface there and its
Coulomb coefficient: an engaged transfer unit's (lifted at least its ``engage_height``, its
rollers carrying at ``surface_speed`` along its axis), else the first belt in cell order whose
surface holds the point, else the floor.

A straight belt is a rectangle moving along its direction at its speed. A curved belt is an
annular sector moving as a rigid rotation about its centre ``c`` at ``omega = direction * speed /
centre_radius`` [rad/s]: at ``p`` the velocity ``omega x (p - c)``, the spin ``omega``. Over a
substep ``h`` the drive (``h > 0``) uses the chord velocity of that rotation,
``(R(omega h) r - r) / h`` with ``r = p - c``: a part that sticks takes it, and ``x += h v`` lands
it exactly on the rotated point, on its arc (``omega x r`` itself would drift it outward by
``r (omega h)^2 / 2`` per substep, 0.5 mm per metre at r = 0.5 m and 1 kHz); its spin ``omega``
turns its yaw with the surface.
"""

import math
from typing import Sequence

from numba import njit
import numpy as np

from conveyor_twin.cell.model import Actuator, Belt

# --- belt table columns (straight belts: 0 .. BT_DV; curves: BT_KIND .. BT_OMEGA) ---
BT_SX = 0             # start [m]
BT_SY = 1
BT_DX = 2             # running direction (unit)
BT_DY = 3
BT_LENGTH = 4         # [m] (curve: of the centre line)
BT_HALF_WIDTH = 5     # [m]
BT_MU = 6
BT_DV = 7             # largest speed change per step [m/s]
BT_KIND = 8           # KIND_STRAIGHT or KIND_CURVE
BT_CX = 9             # curve: centre [m]
BT_CY = 10
BT_R_IN2 = 11         # curve: inner radius squared [m^2]
BT_R_OUT2 = 12        # curve: outer radius squared [m^2]
BT_START = 13         # curve: start angle [rad]
BT_SWEEP = 14         # curve: signed sweep [rad] (the sign is the direction)
BT_OMEGA = 15         # curve: angular speed per belt speed, direction / centre radius [1/m]
BT_UX = 16            # curve: unit vector from the centre to the start edge, turned by
BT_UY = 17            #   -direction * 90 deg (so a point is past the start edge if u . r >= 0)
BT_EX = 18            # curve: the same for the end edge, turned by +direction * 90 deg
BT_EY = 19
BT_SECTOR = 20        # curve: SECTOR_NARROW (sweep <= pi), SECTOR_WIDE, SECTOR_FULL (2 pi)
BT_ROT_S = 21         # curve, per substep (prepare_rotations): sin(omega h) / h [1/s]
BT_ROT_C = 22         #   (cos(omega h) - 1) / h [1/s]
BT_COLUMNS = 23

KIND_STRAIGHT = 0.0
KIND_CURVE = 1.0
SECTOR_NARROW = 0.0
SECTOR_WIDE = 1.0
SECTOR_FULL = 2.0
# Points this close to a curve's start or end edge [m] count as on it (as in Belt.contains).
EDGE_TOLERANCE = 1e-9

# --- transfer table columns ---
TR_ACTUATOR = 0       # index into the cell's actuators (and the position arrays)
TR_X = 1              # centre of the footprint [m]
TR_Y = 2
TR_AX = 3             # carrying direction (unit)
TR_AY = 4
TR_HALF_LENGTH = 5    # [m], along the axis
TR_HALF_WIDTH = 6     # [m]
TR_ENGAGE = 7         # lift from which the rollers carry [m]
TR_SPEED = 8          # carrying speed [m/s]
TR_MU = 9
TR_COLUMNS = 10

def belt_table(belts: Sequence[Belt], dt: float) -> np.ndarray:
    """Return the (B, BT_COLUMNS) table of the belts for step ``dt`` [s]."""
    table = np.zeros((len(belts), BT_COLUMNS), dtype=np.float64)
    for i, b in enumerate(belts):
        c = b.curve
        if c is None:
            d = b.direction
            table[i, :BT_KIND + 1] = (b.start[0], b.start[1], d[0], d[1], b.length,
                                      0.5 * b.width, b.friction, b.acceleration * dt,
                                      KIND_STRAIGHT)
            continue
        table[i, :BT_KIND + 1] = (b.start[0], b.start[1], 0.0, 0.0, b.length, 0.5 * b.width,
                                  b.friction, b.acceleration * dt, KIND_CURVE)
        sweep = c.sweep
        end = c.start_angle + sweep
        turn = math.copysign(1.0, sweep)
        sector = (SECTOR_FULL if abs(sweep) >= 2.0 * math.pi
                  else SECTOR_WIDE if abs(sweep) > math.pi else SECTOR_NARROW)
        table[i, BT_CX:BT_ROT_S] = (
            c.centre[0], c.centre[1], c.inner_radius ** 2, c.outer_radius ** 2, c.start_angle,
            sweep, c.direction / c.centre_radius,
            -turn * math.sin(c.start_angle), turn * math.cos(c.start_angle),
            turn * math.sin(end), -turn * math.cos(end), sector)
    return table


def transfer_table(actuators: Sequence[Actuator]) -> np.ndarray:
    """Return the (T, TR_COLUMNS) table of the cell's ``transfer`` actuators."""
    rows = []
    for k, a in enumerate(actuators):
        if a.kind != 'transfer':
            continue
        norm = math.hypot(a.axis[0], a.axis[1])
        if not norm > 0.0:
            raise ValueError(f'actuator {a.name!r}: axis {a.axis} has no direction')
        rows.append((k, a.base[0], a.base[1], a.axis[0] / norm, a.axis[1] / norm,
                     0.5 * a.length, 0.5 * a.width, a.engage_height, a.surface_speed,
                     a.friction))
    return np.array(rows, dtype=np.float64).reshape(-1, TR_COLUMNS)


@njit(cache=True, inline='always')
def _on_straight(belts, b, px, py):
    rx = px - belts[b, BT_SX]
    ry = py - belts[b, BT_SY]
    dx = belts[b, BT_DX]
    dy = belts[b, BT_DY]
    u = rx * dx + ry * dy
    w = ry * dx - rx * dy
    return 0.0 <= u <= belts[b, BT_LENGTH] and abs(w) <= belts[b, BT_HALF_WIDTH]


@njit(cache=True, inline='always')
def _in_sector(belts, b, rx, ry):
    """True if the point at ``r = p - c`` [m] from curve ``b``'s centre lies on its surface."""
    r2 = rx * rx + ry * ry
    if r2 < belts[b, BT_R_IN2] or r2 > belts[b, BT_R_OUT2]:
        return False
    sector = belts[b, BT_SECTOR]
    if sector == SECTOR_FULL:
        return True
    past_start = belts[b, BT_UX] * rx + belts[b, BT_UY] * ry >= -EDGE_TOLERANCE
    before_end = belts[b, BT_EX] * rx + belts[b, BT_EY] * ry >= -EDGE_TOLERANCE
    if sector == SECTOR_NARROW:
        return past_start and before_end
    return past_start or before_end


@njit(cache=True)
def prepare_rotations(belts, speed, h):
    """Store each curve's rotation over the substep ``h`` [s] (``BT_ROT_S``, ``BT_ROT_C``) for
    :func:`surface_under`'s chord velocities; straight belts are left alone."""
    for b in range(belts.shape[0]):
        if belts[b, BT_KIND] == KIND_STRAIGHT:
            continue
        angle = speed[b] * belts[b, BT_OMEGA] * h
        belts[b, BT_ROT_S] = math.sin(angle) / h
        # cos(angle) - 1 without cancellation
        belts[b, BT_ROT_C] = -2.0 * math.sin(0.5 * angle) ** 2 / h


@njit(cache=True, inline='always')
def transfer_under(transfers, position, px, py):
    """Return the row of the first engaged transfer unit whose footprint holds p [m], or -1.

    :param position: float64[A] the actuators' positions (a transfer's: its lift [m]).
    """
    for k in range(transfers.shape[0]):
        if position[int(transfers[k, TR_ACTUATOR])] < transfers[k, TR_ENGAGE]:
            continue
        rx = px - transfers[k, TR_X]
        ry = py - transfers[k, TR_Y]
        ax = transfers[k, TR_AX]
        ay = transfers[k, TR_AY]
        if (abs(rx * ax + ry * ay) <= transfers[k, TR_HALF_LENGTH]
                and abs(ry * ax - rx * ay) <= transfers[k, TR_HALF_WIDTH]):
            return k
    return -1


@njit(cache=True, inline='always')
def all_straight(belts):
    """True if every belt of the table is straight."""
    for b in range(belts.shape[0]):
        if belts[b, BT_KIND] != KIND_STRAIGHT:
            return False
    return True


@njit(cache=True, inline='always')
def straight_belt_surface(belts, speed, px, py, floor_mu):
    """:func:`belt_surface` for a table of straight belts only (:func:`all_straight`): the
    same operations without the tests for curves, so a straight-only cell steps as fast as
    before curves existed."""
    for b in range(belts.shape[0]):
        if _on_straight(belts, b, px, py):
            return (speed[b] * belts[b, BT_DX], speed[b] * belts[b, BT_DY], 0.0,
                    belts[b, BT_MU])
    return 0.0, 0.0, 0.0, floor_mu


@njit(cache=True, inline='always')
def belt_surface(belts, speed, px, py, floor_mu, h):
    """Return (v_x [m/s], v_y [m/s], spin [rad/s], mu) of the belt under the point p [m], or
    the floor's: :func:`surface_under` without the transfer units.

    A cell without transfer units steps through this one (no transfer lookup at all).
    """
    for b in range(belts.shape[0]):
        if belts[b, BT_KIND] == KIND_STRAIGHT:
            if _on_straight(belts, b, px, py):
                return (speed[b] * belts[b, BT_DX], speed[b] * belts[b, BT_DY], 0.0,
                        belts[b, BT_MU])
            continue
        rx = px - belts[b, BT_CX]
        ry = py - belts[b, BT_CY]
        if not _in_sector(belts, b, rx, ry):
            continue
        if h > 0.0:
            s = belts[b, BT_ROT_S]
            c = belts[b, BT_ROT_C]
            return (c * rx - s * ry, s * rx + c * ry, speed[b] * belts[b, BT_OMEGA],
                    belts[b, BT_MU])
        omega = speed[b] * belts[b, BT_OMEGA]
        return -omega * ry, omega * rx, omega, belts[b, BT_MU]
    return 0.0, 0.0, 0.0, floor_mu


@njit(cache=True, inline='always')
def surface_under(surfaces, speed, px, py, floor_mu, h):
    """Return (v_x [m/s], v_y [m/s], spin [rad/s], mu) of the surface under the point p [m].

    :param surfaces: ``(belts, transfers, transfer_position, footprint)`` (see
        :func:`~conveyor_twin.micro.drive.belt_drive`); ``speed`` the belts' speeds [m/s].
    :param h: on a curve, > 0: the chord velocity of the rotation over the substep ``h`` [s]
        (what a sticking part takes; :func:`prepare_rotations` must have stored that
        rotation); 0: the instantaneous velocity ``omega x r``.
    """
    belts, transfers, position, _footprint = surfaces
    k = transfer_under(transfers, position, px, py)
    if k >= 0:
        s = transfers[k, TR_SPEED]
        return s * transfers[k, TR_AX], s * transfers[k, TR_AY], 0.0, transfers[k, TR_MU]
    return belt_surface(belts, speed, px, py, floor_mu, h)
