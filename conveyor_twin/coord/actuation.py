"""Belt speeds and actuator positions: targets, rate limits, stalls and the per-step update.

The coordinator owns these so every scale sees the same belt speeds and actuator positions at a
step, whatever the process layout. An actuator with a finite ``force_limit`` stalls when the
load the micro scale measured over a step exceeds it (:meth:`Actuation.observe`; the rule is
:mod:`conveyor_twin.micro.actuator_load`'s).
"""

from typing import Optional

import numpy as np

from conveyor_twin.cell.model import Cell
# the one rate limit both scales use, and the stall rule (numba)
from conveyor_twin.micro.actuator_load import (ST_OVERLOAD, ST_STALLED, stall_observe,
                                               stall_ramp, STALL_ROWS)
from conveyor_twin.micro.drive import ramp
from conveyor_twin.wire.diagnostics import OK, Status, WARN

#: Name of the diagnostics status of the actuators' stalls.
ACTUATOR_STATUS = 'conveyor_twin: actuators'


class Actuation:
    """Targets and actual values of every belt speed [m/s] and actuator position [m or rad],
    the actuators' loads [N] and stalls."""

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
        #: Largest force every actuator exerts on parts [N] (``inf``: unlimited).
        self.force_limit = np.array([a.force_limit for a in cell.actuators], dtype=np.float64)
        #: Mean normal force of the parts on every actuator during the last step [N].
        self.actuator_load = np.zeros(len(cell.actuators))
        self._stall = np.zeros((STALL_ROWS, len(cell.actuators)))
        self._limited = bool(np.isfinite(self.force_limit).any())
        self._names = [a.name for a in cell.actuators]
        self._hardware_id = cell.settings.name

    @property
    def stalled(self) -> np.ndarray:
        """True for every actuator stalled after the last step (a new array)."""
        return self._stall[ST_STALLED] != 0.0

    @property
    def stall_flags(self) -> np.ndarray:
        """1.0 for every actuator stalled after the last step, else 0.0 (a view)."""
        return self._stall[ST_STALLED]

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
        """Move every actual value one step toward its target within its rate limit (a
        stalled actuator backs off or retries)."""
        ramp(self.belt_speed, self.belt_target, self._belt_dv)
        if self._limited:
            stall_ramp(self.actuator_position, self.actuator_target, self._actuator_dx,
                       self._stall)
        else:
            ramp(self.actuator_position, self.actuator_target, self._actuator_dx)

    @property
    def overload(self) -> np.ndarray:
        """The load of every actuator's last step over its limit [N] (0: never; a view)."""
        return self._stall[ST_OVERLOAD]

    def observe(self, load: Optional[np.ndarray]) -> None:
        """Take the load [N] every actuator carried in the step just taken (the micro
        scale's measure; None: not measured, kept at zero) and update the stalls."""
        if load is None or load.size == 0:
            return
        self.actuator_load[:] = load
        if self._limited:
            stall_observe(self.actuator_position, self.actuator_target, self.actuator_load,
                          self.force_limit, self._stall)

    def status(self) -> Optional[Status]:
        """The actuators' diagnostics status: WARN naming every stalled actuator with its load
        and limit, OK with none; None if no actuator has a force limit."""
        if not self._limited:
            return None
        stalled = np.flatnonzero(self._stall[ST_STALLED])
        values = [(f'{self._names[a]}_load_N', f'{self.actuator_load[a]:.1f}')
                  for a in range(len(self._names)) if np.isfinite(self.force_limit[a])]
        if not stalled.size:
            return Status(OK, ACTUATOR_STATUS, 'no actuator stalled', self._hardware_id, values)
        message = '; '.join(f'{self._names[a]} stalled: load {self._stall[ST_OVERLOAD, a]:.1f} '
                            f'N over its force_limit {self.force_limit[a]:g} N' for a in stalled)
        return Status(WARN, ACTUATOR_STATUS, message, self._hardware_id, values)
