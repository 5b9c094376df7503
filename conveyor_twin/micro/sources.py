"""Parts entering: placement without overlap, and the cell's sources (rate, pattern, seed).

Each source draws from its own in-kernel SplitMix64 stream seeded from the run's seed, the
source's ``seed`` and its index, so the same seed gives the same parts bit for bit. Arrivals:
``uniform`` every ``1/rate`` s, ``poisson`` exponential gaps of mean ``1/rate``, ``burst``
``burst_size`` parts every ``burst_size/rate`` s, from ``start_time`` on, at most ``max_parts``.
A due part is tried at up to :data:`PLACE_ATTEMPTS` random poses in the source's region per
step; a pose overlapping a part, an obstacle or a solid actuator is refused and the part waits
for the next step (parts are delayed, never dropped, never overlapping).
"""

import math
from typing import Sequence

from numba import njit
import numpy as np

from conveyor_twin.cell.model import Cell, Source
from conveyor_twin.micro.collide import collide
from conveyor_twin.micro.contacts.narrow_phase import part_shape
from conveyor_twin.micro.contacts.tables import (AS_ACTIVE, AS_NV, AS_R, AS_XMAX, AS_XMIN, AS_YMAX,
                                                 AS_YMIN, SH_NV, SH_OFF, SH_R, SH_XMAX, SH_XMIN,
                                                 SH_YMAX, SH_YMIN)
from conveyor_twin.micro.drive import surface_velocity
from conveyor_twin.micro.state import (C_ENTERED, C_N, C_NEXT_ID, P_VX, P_VY, P_WZ, P_X, P_X_PREV,
                                       P_Y, P_Y_PREV, P_YAW, P_YAW_PREV, PT_BRAD)

PLACE_ATTEMPTS = 16

PATTERN_UNIFORM = 0
PATTERN_POISSON = 1
PATTERN_BURST = 2
_PATTERNS = {'uniform': PATTERN_UNIFORM, 'poisson': PATTERN_POISSON, 'burst': PATTERN_BURST}

# --- source table columns ---
SR_TYPE = 0
SR_X0 = 1
SR_Y0 = 2
SR_X1 = 3
SR_Y1 = 4
SR_RATE = 5
SR_PATTERN = 6
SR_BURST = 7
SR_BELT_VELOCITY = 8  # 1: initial velocity of the belt surface
SR_VX = 9
SR_VY = 10
SR_RANDOM_YAW = 11    # 1: uniformly random yaw
SR_YAW = 12
SR_START = 13
SR_MAX = 14
SR_COLUMNS = 15

# --- source state columns (int64) ---
SS_PENDING = 0
SS_SPAWNED = 1
SS_COLUMNS = 2

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)


def source_table(cell: Cell, sources: Sequence[Source]) -> np.ndarray:
    """Return the (S, SR_COLUMNS) table of the sources."""
    table = np.zeros((len(sources), SR_COLUMNS), dtype=np.float64)
    for i, s in enumerate(sources):
        row = table[i]
        row[SR_TYPE] = cell.part_type_index(s.part_type)
        row[SR_X0:SR_Y1 + 1] = s.region
        row[SR_RATE] = s.rate
        row[SR_PATTERN] = _PATTERNS[s.pattern]
        row[SR_BURST] = s.burst_size
        row[SR_BELT_VELOCITY] = 1.0 if s.velocity is None else 0.0
        if s.velocity is not None:
            row[SR_VX], row[SR_VY] = s.velocity
        row[SR_RANDOM_YAW] = 1.0 if s.yaw is None else 0.0
        row[SR_YAW] = s.yaw or 0.0
        row[SR_START] = s.start_time
        row[SR_MAX] = s.max_parts
    return table


def seed_streams(seed: int, sources: Sequence[Source]) -> np.ndarray:
    """Return the initial SplitMix64 state of every source's stream (uint64)."""
    mask = (1 << 64) - 1
    states = np.zeros(len(sources), dtype=np.uint64)
    for i, s in enumerate(sources):
        value = (seed * 0x9E3779B97F4A7C15 + s.seed * 0xD1B54A32D192ED03
                 + (i + 1) * 0x8CB92BA72F3D8DD7) & mask
        states[i] = np.uint64(value)
    return states


@njit(cache=True)
def next_u64(rng, s):
    """Advance stream ``s`` of ``rng`` (uint64 array) and return its next output (SplitMix64)."""
    z = rng[s] + _GOLDEN
    rng[s] = z
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@njit(cache=True)
def uniform(rng, s):
    """Return the next uniform float in [0, 1) of stream ``s``."""
    return float(next_u64(rng, s) >> _S11) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def overlaps(t, px, py, yaw, n, ptype, P, pt, shp, shp_verts, act_state, act_verts,
             va, vb, out):
    """Return True if a part of type t at (p [m], yaw [rad]) would overlap anything solid."""
    na, ra = part_shape(pt, t, px, py, yaw, va)
    br = pt[t, PT_BRAD]
    x = P[P_X]
    y = P[P_Y]
    for j in range(n):
        tj = ptype[j]
        rr = br + pt[tj, PT_BRAD]
        dx = x[j] - px
        dy = y[j] - py
        if dx * dx + dy * dy >= rr * rr:
            continue
        nb, rb = part_shape(pt, tj, x[j], y[j], P[P_YAW, j], vb)
        if collide(va, na, ra, vb, nb, rb, out) > 0:
            return True
    for s in range(shp.shape[0]):
        if (px + br <= shp[s, SH_XMIN] or px - br >= shp[s, SH_XMAX]
                or py + br <= shp[s, SH_YMIN] or py - br >= shp[s, SH_YMAX]):
            continue
        off = int(shp[s, SH_OFF])
        nv = int(shp[s, SH_NV])
        if collide(va, na, ra, shp_verts[off:off + nv], nv, shp[s, SH_R], out) > 0:
            return True
    for a in range(act_state.shape[0]):
        if act_state[a, AS_ACTIVE] == 0.0:
            continue
        if (px + br <= act_state[a, AS_XMIN] or px - br >= act_state[a, AS_XMAX]
                or py + br <= act_state[a, AS_YMIN] or py - br >= act_state[a, AS_YMAX]):
            continue
        if collide(va, na, ra, act_verts[a], int(act_state[a, AS_NV]), act_state[a, AS_R],
                   out) > 0:
            return True
    return False


@njit(cache=True)
def place(t, px, py, yaw, pvx, pvy, pwz, micro):
    """Append a part unless it overlaps or the capacity is full; return its id or 0.

    :param t: part type index; ``px``, ``py`` [m], ``yaw`` [rad]; ``pvx``, ``pvy`` [m/s],
        ``pwz`` [rad/s].
    :param micro: ``(counters, ids, ptype, P, pt, shp, shp_verts, act_state, act_verts, va, vb,
        out)``: the parts' state, the part types, the static shapes and the actuators (as in
        :func:`overlaps`) and the scratch of the narrow phase (unpacked here, no copies).
    """
    counters, ids, ptype, P, pt, shp, shp_verts, act_state, act_verts, va, vb, out = micro
    n = counters[C_N]
    if n >= ids.size:
        return np.uint32(0)
    if overlaps(t, px, py, yaw, n, ptype, P, pt, shp, shp_verts, act_state, act_verts,
                va, vb, out):
        return np.uint32(0)
    pid = np.uint32(counters[C_NEXT_ID])
    counters[C_NEXT_ID] += 1
    counters[C_ENTERED] += 1
    counters[C_N] = n + 1
    ids[n] = pid
    ptype[n] = t
    P[P_X, n] = px
    P[P_Y, n] = py
    P[P_YAW, n] = yaw
    P[P_VX, n] = pvx
    P[P_VY, n] = pvy
    P[P_WZ, n] = pwz
    P[P_X_PREV, n] = px
    P[P_Y_PREV, n] = py
    P[P_YAW_PREV, n] = yaw
    return pid


@njit(cache=True)
def run_sources(time, sources, surfaces, belt_speed, floor_mu, micro):
    """Let every source release the parts due by ``time`` [s] (at the start of a step).

    :param sources: ``(src, src_next, src_state, rng)``: the source table, each source's next
        arrival [s], its pending and spawned counts and its random stream.
    :param surfaces: the surfaces (see :func:`~conveyor_twin.micro.drive.belt_drive`),
        ``belt_speed`` the belts' speeds [m/s], ``floor_mu`` the floor's friction: a source
        without a velocity gives its parts the velocity and spin of the surface under them
        (:func:`~conveyor_twin.micro.drive.surface_velocity`; on a curve its rotation).
    :param micro: what :func:`place` takes.
    """
    src, src_next, src_state, rng = sources
    for s in range(src.shape[0]):
        limit = int(src[s, SR_MAX])
        pattern = int(src[s, SR_PATTERN])
        rate = src[s, SR_RATE]
        while src_next[s] <= time and (
                limit == 0 or src_state[s, SS_SPAWNED] + src_state[s, SS_PENDING] < limit):
            due = int(src[s, SR_BURST]) if pattern == PATTERN_BURST else 1
            if limit:
                due = min(due, limit - src_state[s, SS_SPAWNED] - src_state[s, SS_PENDING])
            src_state[s, SS_PENDING] += due
            if pattern == PATTERN_POISSON:
                src_next[s] += -math.log(1.0 - uniform(rng, s)) / rate
            elif pattern == PATTERN_BURST:
                src_next[s] += src[s, SR_BURST] / rate
            else:
                src_next[s] += 1.0 / rate
        attempts = 0
        t = int(src[s, SR_TYPE])
        while src_state[s, SS_PENDING] > 0 and attempts < PLACE_ATTEMPTS:
            attempts += 1
            px = src[s, SR_X0] + uniform(rng, s) * (src[s, SR_X1] - src[s, SR_X0])
            py = src[s, SR_Y0] + uniform(rng, s) * (src[s, SR_Y1] - src[s, SR_Y0])
            if src[s, SR_RANDOM_YAW] != 0.0:
                yaw = (2.0 * uniform(rng, s) - 1.0) * math.pi
            else:
                yaw = src[s, SR_YAW]
            if src[s, SR_BELT_VELOCITY] != 0.0:
                pvx, pvy, pwz, _ = surface_velocity(surfaces, belt_speed, px, py, floor_mu)
            else:
                pvx = src[s, SR_VX]
                pvy = src[s, SR_VY]
                pwz = 0.0
            pid = place(t, px, py, yaw, pvx, pvy, pwz, micro)
            if pid != 0:
                src_state[s, SS_PENDING] -= 1
                src_state[s, SS_SPAWNED] += 1
