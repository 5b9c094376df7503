"""The load the parts put on each actuator, and the stall of a force-limited actuator.

Load: the micro kernel adds, after each substep's contact response, the normal impulse of every
contact whose kinematic body is actuator ``a`` divided by the step, so after a step ``load[a]``
is the mean normal force the parts put on it during that step [N] (on a diverter: the sum of
the forces at its contact points, not a torque). Penalty model: the spring-damper force times
the substep. Impulse model: the accumulated ``CT_LN`` [N s] plus ``k d h`` for an overlap ``d``
(``k`` the cell's ``penalty_stiffness``): a part squeezed between rigid bodies takes whatever
impulse the sweeps give it, which grows with the part's mass and speed rather than with the
squeeze, while the overlap the position correction removes is the squeeze; its spring force
is the load that holds it, as in the penalty model.

Stall (:func:`stall_ramp`, :func:`stall_observe`, run by the coordinator, which owns the
positions every scale uses): when an actuator's load over a step exceeds its ``force_limit``
it stalls and holds where that step ended (a part caught between it and a wall is squeezed by
at most one step's travel). While the load stays above the limit it holds; when it falls, it
retries: one step toward its target; a retry that overloads it again goes back to the hold
position, one that does not clears the stall and the actuator moves on by itself. A command
to the other side (retract) is obeyed at once and clears the stall. The decision of step ``k``
acts from step ``k + 1`` on (the coordinator learns the load after the micro scale stepped).
"""

from numba import njit

from conveyor_twin.micro.contacts.tables import (CT_BVX, CT_BVY, CT_BW, CT_DEPTH, CT_KB, CT_LN,
                                                 CT_NX, CT_NY, CT_RAX, CT_RAY, CT_RBX, CT_RBY,
                                                 MP_DAMPING, MP_STIFFNESS)

# --- rows of the stall state ``stall`` (STALL_ROWS, A) ---
ST_STALLED = 0        # 1.0 while stalled
ST_HOLD = 1           # where it holds [m or rad]
ST_DIRECTION = 2      # sign of the motion that overloaded it (0: it stood still)
ST_PREVIOUS = 3       # position at the start of the step [m or rad]
ST_RETRY = 4          # 1.0: advance one step in the next step (the load fell)
ST_OVERLOAD = 5       # the load of its last step over the limit [N]
STALL_ROWS = 6


@njit(cache=True)
def add_actuator_load(nc, ct, cidx, n_static, velocity, mp, h, inv_dt, penalty, load):
    """Add the normal force of every actuator contact of a substep to ``load`` [N].

    Contacts with actuator ``a`` are those with ``cidx[c, 1] == -1`` and the second key
    ``CT_KB = 2 (n_static + a) + point``. Impulse model: adds ``(CT_LN + k max(d, 0) h) / dt``
    (call after the impulse sweeps); penalty model: ``max(0, k d - c u_n) h / dt`` (call with
    the velocities the penalty forces used); ``k``, ``c``: ``mp[MP_STIFFNESS]``,
    ``mp[MP_DAMPING]``, ``d`` the depth.

    :param velocity: ``(vx, vy, wz)`` of the parts [m/s, rad/s]. :param h: substep [s].
    :param inv_dt: 1 / step [1/s]. :param load: float64[A], accumulated over the step [N].
    """
    na = load.size
    if na == 0:
        return
    vx, vy, wz = velocity
    first = 2.0 * n_static
    k = mp[MP_STIFFNESS]
    damping = mp[MP_DAMPING]
    for c in range(nc):
        if cidx[c, 1] >= 0 or ct[c, CT_KB] < first:
            continue
        a = int(ct[c, CT_KB] * 0.5) - n_static
        if a >= na:
            continue
        if not penalty:
            # the impulses, and the spring force that holds what overlap is left
            load[a] += (ct[c, CT_LN] + k * max(ct[c, CT_DEPTH], 0.0) * h) * inv_dt
            continue
        i = cidx[c, 0]
        nx = ct[c, CT_NX]
        ny = ct[c, CT_NY]
        # the part's contact point velocity relative to the actuator's, along the normal
        rbx = ct[c, CT_RBX]
        rby = ct[c, CT_RBY]
        ux = (vx[i] - wz[i] * ct[c, CT_RAY]) - (ct[c, CT_BVX] - ct[c, CT_BW] * rby)
        uy = (vy[i] + wz[i] * ct[c, CT_RAX]) - (ct[c, CT_BVY] + ct[c, CT_BW] * rbx)
        un = ux * nx + uy * ny
        fn = k * ct[c, CT_DEPTH] - damping * un
        if fn > 0.0:
            load[a] += fn * h * inv_dt


@njit(cache=True)
def _sign(x):
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


@njit(cache=True)
def stall_ramp(position, target, limit, stall):
    """Move every actuator one step toward its target within ``limit``, honouring stalls.

    Not stalled: as :func:`conveyor_twin.micro.drive.ramp`. Stalled, with the target on the
    side of the overloading motion: back to ``ST_HOLD`` after a retry that overloaded it, a
    retry toward the target when the load fell, else it holds; with the target elsewhere
    (retract): toward it. Records the start positions in ``stall[ST_PREVIOUS]``.
    """
    for a in range(position.size):
        p = position[a]
        stall[ST_PREVIOUS, a] = p
        goal = target[a]
        if stall[ST_STALLED, a] != 0.0:
            d = stall[ST_DIRECTION, a]
            if d != 0.0 and _sign(goal - p) == d:
                if p != stall[ST_HOLD, a]:
                    goal = stall[ST_HOLD, a]
                elif stall[ST_RETRY, a] == 0.0:
                    goal = p
        diff = goal - p
        if abs(diff) <= limit[a]:
            position[a] = goal
        elif diff > 0.0:
            position[a] = p + limit[a]
        else:
            position[a] = p - limit[a]


@njit(cache=True)
def stall_observe(position, target, load, force_limit, stall):
    """Update the stalls from the step's ``load`` [N] (after the stages took the step).

    Over the limit: a new stall holds where the step ended, in the direction it moved (or
    toward its target if it stood still); a stalled actuator stops retrying. Within it: a
    stalled actuator that held or backed off retries next step; one that advanced (the retry
    went through) or moved away clears its stall.
    """
    for a in range(position.size):
        start = stall[ST_PREVIOUS, a]
        step_dir = _sign(position[a] - start)
        if load[a] > force_limit[a]:
            stall[ST_OVERLOAD, a] = load[a]
            if stall[ST_STALLED, a] == 0.0:
                stall[ST_STALLED, a] = 1.0
                stall[ST_HOLD, a] = position[a]
                stall[ST_DIRECTION, a] = (step_dir if step_dir != 0.0
                                          else _sign(target[a] - start))
            stall[ST_RETRY, a] = 0.0
        elif stall[ST_STALLED, a] != 0.0:
            d = stall[ST_DIRECTION, a]
            if d != 0.0 and step_dir != d and _sign(target[a] - position[a]) == d:
                stall[ST_RETRY, a] = 1.0  # held or backed off, target still ahead: retry
            else:
                stall[ST_STALLED, a] = 0.0
                stall[ST_RETRY, a] = 0.0
