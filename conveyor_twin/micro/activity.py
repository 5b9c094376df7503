"""Activity (Rideout and Stein) of the penalty contact model, and the stiffness picker.

The activity of an element over a run is ``A = integral |effort * flow| dt``, its absolute power
integrated: contact springs ``|k d * d'|``, contact dampers ``|c u_n^2|``, contact friction
``|f_t u_t|``, belt friction ``|F * slip|`` and the part inertias ``|d(kinetic energy)/dt|``
(summed per element class by :class:`~conveyor_twin.micro.sim.MicroSim` when tracking). The
springs are parasitic: they stand in for rigid contacts. G. Rideout and J. L. Stein (*An
Energy-Based Approach to Parameterizing Parasitic Elements for Eliminating Derivative
Causality*) size such an element so its activity stays a small fraction (1 %) of the least
active *physical* element's. Physical classes below 1 % of the total physical activity are
left out of that minimum (the model reduction of Rideout and Stein would drop them; e.g. the
inertia of parts resting in a jam).

Impacts put a fixed share of their energy through the springs whatever their stiffness, so the
picker is meant for sustained contact (a jam): start it from settled positions.
"""

from dataclasses import dataclass, field, replace
import math
from typing import Dict, List, Optional, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell, ContactModel
from conveyor_twin.micro.sim import MicroSim

PHYSICAL = ('belt_friction', 'part_inertia', 'contact_friction')
PARASITIC = 'contact_springs'
# Physical classes below this share of the total physical activity are left out.
NEGLIGIBLE_SHARE = 0.01


def least_physical(activity: Dict[str, float]) -> float:
    """Return the activity of the least active relevant physical element class [J]."""
    values = [activity[k] for k in PHYSICAL]
    total = sum(values)
    relevant = [v for v in values if v >= NEGLIGIBLE_SHARE * total]
    return min(relevant) if relevant else 0.0


def spring_ratio(activity: Dict[str, float]) -> float:
    """Return the contact springs' activity over the least active physical element's."""
    reference = least_physical(activity)
    return activity[PARASITIC] / reference if reference > 0.0 else math.inf


@dataclass
class StiffnessPick:
    """Result of :func:`pick_contact_stiffness`.

    :param stiffness: picked spring [N/m]. :param damping: its damper [N s/m].
    :param ratio: springs' activity over the least active physical element's.
    :param trials: (stiffness, ratio) of every run.
    """

    stiffness: float
    damping: float
    ratio: float
    activity: Dict[str, float]
    trials: List[Tuple[float, float]] = field(default_factory=list)


def run_activity(cell: Cell, stiffness: float, damping: float, *, seed: int, duration: float,
                 settle: float = 0.0, positions: Optional[np.ndarray] = None,
                 part_type: int = 0) -> Dict[str, float]:
    """Run the cell with the penalty model; return the activities [J] of the last ``duration``.

    :param settle: time run first and not counted [s] (arrival impacts, initial transients).
    :param positions: (n, 2) initial part centres [m], each given the surface velocity of the
        belt under it (at rest off the belts).
    """
    micro = replace(cell.micro, contact=ContactModel.PENALTY, penalty_stiffness=stiffness,
                    penalty_damping=damping)
    sim = MicroSim(replace(cell, micro=micro), seed=seed, track_activity=True)
    if positions is not None and len(positions):
        velocity = np.array([belt_velocity_at(cell, (float(x), float(y)))
                             for x, y in positions]).reshape(-1, 2)
        sim.spawn(part_type, positions[:, 0], positions[:, 1], 0.0,
                  vx=velocity[:, 0], vy=velocity[:, 1], strict=False)
    dt = cell.settings.step
    if settle > 0.0:
        sim.step(int(round(settle / dt)))
        sim.acc[:] = 0.0
    sim.step(max(1, int(round(duration / dt))))
    return sim.activity()


def belt_velocity_at(cell: Cell, point: Tuple[float, float]) -> Tuple[float, float]:
    """Return the velocity [m/s] of the first belt under ``point`` [m] at its speed, or 0."""
    for belt in cell.belts:
        if belt.contains(point):
            return belt.surface_velocity(point, belt.speed)
    return (0.0, 0.0)


def pick_contact_stiffness(cell: Cell, *, seed: int, duration: float,
                           settle: float = 0.0, positions: Optional[np.ndarray] = None,
                           fraction: float = 0.01,
                           stiffness: Optional[float] = None, max_trials: int = 8,
                           max_stiffness: float = 1e9) -> StiffnessPick:
    """Pick the softest contact stiffness whose springs' activity is <= ``fraction`` of the
    least active physical element's (Rideout and Stein), raising it from ``stiffness``
    (default: the cell's) by the measured excess (the springs' activity falls about as 1/k).

    The damping keeps the cell's damping ratio ``c / (2 sqrt(k m_eff))`` (springs first, then
    damping, as Rideout and Stein prefer). Each trial runs the cell for ``settle + duration``
    [s] and measures the last ``duration``.
    """
    k = float(stiffness or cell.micro.penalty_stiffness)
    m_eff = 0.5 * min(p.mass for p in cell.part_types)
    zeta = cell.micro.penalty_damping / (2.0 * math.sqrt(cell.micro.penalty_stiffness * m_eff))
    trials: List[Tuple[float, float]] = []
    pick = None
    for _ in range(max_trials):
        c = 2.0 * zeta * math.sqrt(k * m_eff)
        activity = run_activity(cell, k, c, seed=seed, duration=duration, settle=settle,
                                positions=positions)
        ratio = spring_ratio(activity)
        trials.append((k, ratio))
        pick = StiffnessPick(k, c, ratio, activity, trials)
        if ratio <= fraction or k >= max_stiffness:
            break
        k = min(max_stiffness, k * max(2.0, 1.25 * ratio / fraction))
    return pick
