"""Belt speeds and actuator positions: targets, rate limits and the per-step update.

The coordinator owns these so every scale sees the same belt speeds and actuator positions at a
step, whatever the process layout.
"""

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.micro.drive import ramp  # the one rate limit both scales use (numba)


class Actuation:
    """Targets and actual values of every belt speed [m/s] and actuator position [m or rad]."""

    def __init__(self, cell: Cell) -> None:
        dt = cell.settings.step
        self.belt_target = np.array([b.speed for b in cell.belts], dtype=np.float64)
        self.belt_speed = self.belt_target.copy()
        self._belt_dv = np.array([b.acceleration * dt for b in cell.belts], dtype=np.float64)
        self.actuator_target = np.array([a.initial_position for a in cell.actuators],
                                        dtype=np.float64)
        self.actuator_position = self.actuator_target.copy()
        self._nominal_dx = np.array([a.max_speed * dt for a in cell.actuators],
                                    dtype=np.float64)
        self._actuator_dx = self._nominal_dx.copy()

    def set_actuator_rate_factors(self, factors: np.ndarray) -> None:
        """Move every actuator at ``factors`` [1] x its max speed (1: nominal; 0: stuck)."""
        np.multiply(self._nominal_dx, factors, out=self._actuator_dx)

    def set_belt_target(self, index: int, speed: float) -> None:
        """Set belt ``index``'s target speed [m/s] (already validated)."""
        self.belt_target[index] = speed

    def set_actuator_target(self, index: int, position: float) -> None:
        """Set actuator ``index``'s target position (already validated)."""
        self.actuator_target[index] = position

    def advance(self) -> None:
        """Move every actual value one step toward its target within its rate limit."""
        ramp(self.belt_speed, self.belt_target, self._belt_dv)
        ramp(self.actuator_position, self.actuator_target, self._actuator_dx)

