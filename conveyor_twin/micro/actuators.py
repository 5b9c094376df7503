"""Actuators as kinematic bodies (infinite mass) moving toward their targets at max speed.

``pusher``: a paddle rectangle centred at ``base + position * axis`` (``length`` along the axis,
``width`` across), moving with velocity ``position' * axis``. ``stopper``: a blade rectangle at
``base`` (``length`` along the axis), solid only while lifted at least ``engage_height``.
``diverter``: a capsule arm from the pivot ``base`` of ``length`` and thickness ``width``
pointing along ``axis`` rotated by the position [rad], turning at ``position'`` about the pivot.
``transfer``: no collision shape (never active here); its lift ramps like a stopper's and its
surface is the surface lookup's (:mod:`conveyor_twin.micro.drive`).
Within a step the position is interpolated linearly over the substeps.
"""

import math
from typing import Sequence

from numba import njit
import numpy as np

from conveyor_twin.cell.model import Actuator
from conveyor_twin.micro.contacts.tables import (AS_ACTIVE, AS_COLUMNS, AS_E, AS_MU, AS_NV, AS_PX,
                                                 AS_PY, AS_R, AS_VX, AS_VY, AS_W, AS_XMAX, AS_XMIN,
                                                 AS_YMAX, AS_YMIN)

KIND_PUSHER = 0
KIND_STOPPER = 1
KIND_DIVERTER = 2
KIND_TRANSFER = 3
_KINDS = {'pusher': KIND_PUSHER, 'stopper': KIND_STOPPER, 'diverter': KIND_DIVERTER,
          'transfer': KIND_TRANSFER}

# --- actuator parameter columns ---
AP_KIND = 0
AP_BX = 1
AP_BY = 2
AP_AX = 3
AP_AY = 4
AP_LENGTH = 5
AP_WIDTH = 6
AP_ENGAGE = 7
AP_SPEED = 8          # max speed [m/s or rad/s]
AP_E = 9
AP_MU = 10
AP_LOW = 11
AP_HIGH = 12
AP_COLUMNS = 13


def actuator_table(actuators: Sequence[Actuator]) -> np.ndarray:
    """Return the (A, AP_COLUMNS) parameter table of the actuators."""
    table = np.zeros((len(actuators), AP_COLUMNS), dtype=np.float64)
    for i, a in enumerate(actuators):
        table[i] = (_KINDS[a.kind], a.base[0], a.base[1], a.axis[0], a.axis[1], a.length,
                    a.width, a.engage_height, a.max_speed, a.restitution, a.friction,
                    a.position_range[0], a.position_range[1])
    return table


@njit(cache=True)
def _rect(cx, cy, ax, ay, half_l, half_w, verts):
    bx = -ay
    by = ax
    verts[0, 0] = cx - ax * half_l - bx * half_w
    verts[0, 1] = cy - ay * half_l - by * half_w
    verts[1, 0] = cx + ax * half_l - bx * half_w
    verts[1, 1] = cy + ay * half_l - by * half_w
    verts[2, 0] = cx + ax * half_l + bx * half_w
    verts[2, 1] = cy + ay * half_l + by * half_w
    verts[3, 0] = cx - ax * half_l + bx * half_w
    verts[3, 1] = cy - ay * half_l + by * half_w


@njit(cache=True)
def actuator_shapes(par, position, rate, state, verts):
    """Write every actuator's core, radius, velocity and bounds at ``position``.

    :param par: (A, AP_COLUMNS) parameters. :param position: float64[A] [m or rad].
    :param rate: float64[A] position rate [m/s or rad/s].
    :param state: (A, AS_COLUMNS) output. :param verts: (A, 4, 2) output cores [m].
    """
    for a in range(par.shape[0]):
        kind = int(par[a, AP_KIND])
        ax = par[a, AP_AX]
        ay = par[a, AP_AY]
        bx = par[a, AP_BX]
        by = par[a, AP_BY]
        state[a, AS_E] = par[a, AP_E]
        state[a, AS_MU] = par[a, AP_MU]
        state[a, AS_VX] = 0.0
        state[a, AS_VY] = 0.0
        state[a, AS_W] = 0.0
        state[a, AS_PX] = bx
        state[a, AS_PY] = by
        state[a, AS_ACTIVE] = 1.0
        if kind == KIND_DIVERTER:
            c = math.cos(position[a])
            s = math.sin(position[a])
            dx = c * ax - s * ay
            dy = s * ax + c * ay
            verts[a, 0, 0] = bx
            verts[a, 0, 1] = by
            verts[a, 1, 0] = bx + dx * par[a, AP_LENGTH]
            verts[a, 1, 1] = by + dy * par[a, AP_LENGTH]
            state[a, AS_NV] = 2
            state[a, AS_R] = 0.5 * par[a, AP_WIDTH]
            state[a, AS_W] = rate[a]
        else:
            cx = bx
            cy = by
            if kind == KIND_PUSHER:
                cx += position[a] * ax
                cy += position[a] * ay
                state[a, AS_VX] = rate[a] * ax
                state[a, AS_VY] = rate[a] * ay
            elif kind == KIND_TRANSFER or position[a] < par[a, AP_ENGAGE]:
                state[a, AS_ACTIVE] = 0.0
            _rect(cx, cy, ax, ay, 0.5 * par[a, AP_LENGTH], 0.5 * par[a, AP_WIDTH], verts[a])
            state[a, AS_NV] = 4
            state[a, AS_R] = 0.0
        nv = int(state[a, AS_NV])
        r = state[a, AS_R]
        xmin = 1e300
        ymin = 1e300
        xmax = -1e300
        ymax = -1e300
        for k in range(nv):
            xmin = min(xmin, verts[a, k, 0])
            xmax = max(xmax, verts[a, k, 0])
            ymin = min(ymin, verts[a, k, 1])
            ymax = max(ymax, verts[a, k, 1])
        state[a, AS_XMIN] = xmin - r
        state[a, AS_YMIN] = ymin - r
        state[a, AS_XMAX] = xmax + r
        state[a, AS_YMAX] = ymax + r


def actuator_arrays(count: int):
    """Return preallocated (state (A, AS_COLUMNS), cores (A, 4, 2)) arrays."""
    return np.zeros((count, AS_COLUMNS)), np.zeros((count, 4, 2))
