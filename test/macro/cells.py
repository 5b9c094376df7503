"""Small cells for the macro tests, built from the embedded default by replacing parts."""

import dataclasses
import math
from typing import Sequence, Tuple

from conveyor_twin.cell import Cell, load_cell
from conveyor_twin.cell.curves import BeltCurve
from conveyor_twin.cell.loader_curves import guide_rails
from conveyor_twin.cell.model import Actuator, Belt, Obstacle, Zone

RHO_MAX = 10000.0  # parts/m^2, a round number for the analytic checks


def make_cell(*, region: Tuple[float, float, float, float], resolution: float = 0.01,
              belts: Sequence[Belt] = (), obstacles: Sequence[Obstacle] = (),
              actuators: Sequence[Actuator] = (), step: float = 1e-3,
              variant: str = 'capped', scheme: str = 'upwind', rho_max: float = RHO_MAX,
              epsilon: float = 1.0, mollifier_width: float = 0.0, cfl: float = 0.9) -> Cell:
    """Return the default cell with the given belts, obstacles, actuators and one macro zone."""
    base = load_cell(None)
    return dataclasses.replace(
        base,
        settings=dataclasses.replace(base.settings, step=step),
        belts=tuple(belts), obstacles=tuple(obstacles), actuators=tuple(actuators),
        zones=(Zone('z', 'macro', region, resolution),),
        macro=dataclasses.replace(base.macro, variant=variant, scheme=scheme, rho_max=rho_max,
                                  epsilon=epsilon, mollifier_width=mollifier_width, cfl=cfl))


def belt(start, end, width, speed) -> Belt:
    """Return a belt with generous limits."""
    return Belt('b', tuple(start), tuple(end), width, speed, 10.0, 100.0, 0.3)


def wall(name, p0, p1, thickness=0.01) -> Obstacle:
    """Return a straight wall."""
    return Obstacle(name, 'wall', (tuple(p0), tuple(p1)), thickness=thickness)


def curved_belt(name: str, centre, inner: float, outer: float, start_deg: float, end_deg: float,
                speed: float, direction: int = 1, guide_rails: bool = False) -> Belt:
    """Return a curved belt (annular sector; angles in degrees) with generous limits."""
    curve = BeltCurve(tuple(centre), inner, outer, math.radians(start_deg), math.radians(end_deg),
                      direction, guide_rails)
    rc = curve.centre_radius
    return Belt(name, curve.point(rc, curve.start_angle),
                curve.point(rc, curve.start_angle + curve.sweep), outer - inner, speed, 10.0,
                100.0, 0.3, curve=curve)


def rails_of(*belts: Belt) -> Tuple[Obstacle, ...]:
    """Return the guide rails the loader generates for the curved ``belts``."""
    return guide_rails(belts)
