"""Structure-of-arrays part state with a fixed capacity, and the part-type table.

Parts occupy slots ``0 .. n-1`` of every array, in the order they entered (ids ascending):
removal compacts the arrays and keeps that order, so the published order is stable.
Scalar counters live in one int64 array ``counters`` so the kernels can update them in place;
its slots are the ``C_*`` constants below.
"""

from typing import NamedTuple, Sequence

import numpy as np

from conveyor_twin.cell.model import PartType

# --- part-type table columns (float64 table, one row per part type) ---
PT_SHAPE = 0          # 0 disc, 1 box
PT_RADIUS = 1         # disc radius; 0 for boxes (rounding radius) [m]
PT_HL = 2             # box half length (body x) [m]
PT_HW = 3             # box half width [m]
PT_BRAD = 4           # bounding radius [m]
PT_HEIGHT = 5         # height [m]
PT_MASS = 6           # [kg]
PT_INV_MASS = 7       # [1/kg]
PT_INV_INERTIA = 8    # [1/(kg m^2)]
PT_E = 9              # restitution
PT_MU_S = 10          # static impact friction
PT_MU_K = 11          # sliding impact friction
PT_V_T = 12           # friction transition speed [m/s]
PT_SPIN_ARM = 13      # mean distance of the footprint from the centre [m] (belt torque)
PT_INERTIA = 14       # [kg m^2]
PT_COLUMNS = 15

SHAPE_DISC = 0
SHAPE_BOX = 1

# --- counters ---
C_N = 0               # active parts
C_NEXT_ID = 1         # next id to hand out (ids start at 1, never reused)
C_STEP = 2            # steps taken
C_ENTERED = 3         # parts spawned (sources and explicit spawns)
C_OUTBOX = 4          # parts waiting in the outbox
C_EVENTS = 5          # edge events waiting in the events buffer
C_EVENTS_DROPPED = 6  # edge events lost to a full buffer
C_SUBSTEPS = 7        # substeps of the last step
C_SUBSTEPS_CAPPED = 8  # steps whose substep count hit the cap
C_REGION_LEFT = 9     # parts moved to the outbox so far
C_REMOVED = 10        # parts removed through remove()
C_CONTACTS_FULL = 11  # substeps whose contact buffer was full (contacts dropped)
C_VANISHED = 12       # parts that fell off the line (fault ``parts_vanish``)
C_COUNTERS = 13


def spin_arm(part_type: PartType) -> float:
    """Return the mean distance of the footprint's points from its centre [m].

    With uniform pressure, a part spinning on the belt feels the friction torque
    ``mu m g * spin_arm``. Disc: ``2 R / 3``; box: integrated numerically.
    """
    if part_type.shape == 'disc':
        return 2.0 * part_type.radius / 3.0
    k = 200
    u = (np.arange(k) + 0.5) / k - 0.5
    gx, gy = np.meshgrid(u * part_type.length, u * part_type.width)
    return float(np.mean(np.hypot(gx, gy)))


def part_table(part_types: Sequence[PartType]) -> np.ndarray:
    """Return the (types, PT_COLUMNS) float64 table of the part types."""
    table = np.zeros((len(part_types), PT_COLUMNS), dtype=np.float64)
    for i, p in enumerate(part_types):
        row = table[i]
        if p.shape == 'disc':
            row[PT_SHAPE] = SHAPE_DISC
            row[PT_RADIUS] = p.radius
        else:
            row[PT_SHAPE] = SHAPE_BOX
            row[PT_HL] = 0.5 * p.length
            row[PT_HW] = 0.5 * p.width
        row[PT_BRAD] = p.bounding_radius
        row[PT_HEIGHT] = p.height
        row[PT_MASS] = p.mass
        row[PT_INV_MASS] = 1.0 / p.mass
        row[PT_INV_INERTIA] = 1.0 / p.inertia
        row[PT_INERTIA] = p.inertia
        row[PT_E] = p.restitution
        row[PT_MU_S] = p.friction_static
        row[PT_MU_K] = p.friction_sliding
        row[PT_V_T] = p.friction_transition_speed
        row[PT_SPIN_ARM] = spin_arm(p)
    return table


class PartsView(NamedTuple):
    """Arrays of ``n`` parts (views or copies), one entry per part, SI units."""

    id: np.ndarray          # uint32
    part_type: np.ndarray   # uint16
    x: np.ndarray           # [m]
    y: np.ndarray           # [m]
    yaw: np.ndarray         # [rad], in (-pi, pi]
    vx: np.ndarray          # [m/s]
    vy: np.ndarray          # [m/s]
    wz: np.ndarray          # [rad/s]

    def __len__(self) -> int:  # noqa: D105
        return int(self.id.size)


# --- rows of the float64 part state ``P`` (9, capacity) ---
P_X = 0               # [m]
P_Y = 1               # [m]
P_YAW = 2             # [rad]
P_VX = 3              # [m/s]
P_VY = 4              # [m/s]
P_WZ = 5              # [rad/s]
P_X_PREV = 6          # pose at the start of the last step
P_Y_PREV = 7
P_YAW_PREV = 8
P_ROWS = 9


class PartState:
    """Preallocated part arrays: ``ids``, ``part_type`` and the float rows of ``P``.

    ``x``, ``y``, ``yaw``, ``vx``, ``vy``, ``wz`` (and ``*_prev``, the pose at the start of the
    last step) are views of the contiguous rows of ``P``: a structure of arrays.

    :param capacity: number of part slots.
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = int(capacity)
        self.ids = np.zeros(capacity, dtype=np.uint32)
        self.part_type = np.zeros(capacity, dtype=np.uint16)
        self.P = np.zeros((P_ROWS, capacity), dtype=np.float64)
        (self.x, self.y, self.yaw, self.vx, self.vy, self.wz, self.x_prev, self.y_prev,
         self.yaw_prev) = self.P
        self.counters = np.zeros(C_COUNTERS, dtype=np.int64)
        self.counters[C_NEXT_ID] = 1

    @property
    def n(self) -> int:
        """Number of active parts."""
        return int(self.counters[C_N])

    def view(self) -> PartsView:
        """Return views of the active parts (valid until the next step or removal)."""
        n = self.n
        return PartsView(self.ids[:n], self.part_type[:n], self.x[:n], self.y[:n],
                         self.yaw[:n], self.vx[:n], self.vy[:n], self.wz[:n])
