"""Faults of drives and command paths, applied by the coordinator core (no ROS imports).

Commands: ``command_drop``/``command_delay`` act on a whole command topic, ``*_ignore_commands``
and ``*_delay_commands`` on one belt or actuator; they filter the commands drained at a step
(what was received is still what is recorded, so a re-simulation applies the same faults to the
same commands). Drives: ``belt_stall`` holds the drive at 0 (it ramps up again from 0 once
cleared), ``actuator_stuck``/``actuator_slow`` scale the actuator's rate limit; ``belt_slip``,
``belt_speed_noise`` and ``actuator_offset`` change what the stages get (and what
``belt_states``/``actuator_states`` report as actual) without touching the drive's state.
An offset actuator moves to (and, once cleared, back from) its offset at its own speed (times
any ``actuator_slow`` factor), so what is reported is where every scale's actuator is.
"""

import dataclasses
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.contract import ACTUATOR_COMMAND, BELT_COMMAND
from conveyor_twin.faults.book import CLEAR, fault_rng, FaultEvent, steps_of
from conveyor_twin.faults.model import ActiveFault
from conveyor_twin.micro.drive import ramp

# the coordinator's command kinds (``Command.kind``)
BELT = 'belt'
ACTUATOR = 'actuator'
_TOPIC_KIND = {BELT_COMMAND.name: BELT, ACTUATOR_COMMAND.name: ACTUATOR}
Command = Any  # conveyor_twin.coord.commands.Command (the coordinator sits above this layer)
Actuation = Any  # conveyor_twin.coord.actuation.Actuation
_COMMAND_FAULTS = ('command_drop', 'command_delay', 'belt_ignore_commands',
                   'belt_delay_commands', 'actuator_ignore_commands', 'actuator_delay_commands')
_DRIVE_FAULTS = ('belt_stall', 'belt_slip', 'belt_speed_noise', 'actuator_stuck',
                 'actuator_slow', 'actuator_offset')


class ActuationFaults:
    """The command and drive faults active in the coordinator.

    :param cell: the cell. :param seed: the run's seed (random faults draw from it).
    """

    def __init__(self, cell: Cell, seed: int) -> None:
        self.cell = cell
        self.seed = seed
        self.dt = cell.settings.step
        self.faults: Dict[int, ActiveFault] = {}
        self._rng: Dict[int, np.random.Generator] = {}
        self._delayed: Dict[int, List[Command]] = {}  # step -> commands due then
        self._low = np.array([a.position_range[0] for a in cell.actuators], dtype=np.float64)
        self._high = np.array([a.position_range[1] for a in cell.actuators], dtype=np.float64)
        self._rate = np.ones(len(cell.actuators))
        self._nominal_dx = np.array([a.max_speed * self.dt for a in cell.actuators],
                                    dtype=np.float64)
        self._dx = self._nominal_dx.copy()  # every actuator's move per step now [m or rad]
        # where the actuators are while an offset acts or fades (None: where they are driven)
        self._offset_position: Optional[np.ndarray] = None
        self._goal = np.zeros(len(cell.actuators))
        self._offsets = False  # an actuator_offset fault is active
        self.dropped = 0   # commands lost to faults
        self.delayed = 0   # commands delayed by faults

    @property
    def busy(self) -> bool:
        """True while a fault is active, a delayed command is waiting or an actuator is
        still moving back from a cleared offset."""
        return bool(self.faults or self._delayed) or self._offset_position is not None

    def apply(self, events: Sequence[FaultEvent], actuation: Actuation) -> None:
        """Take the step's events (those of other stages are ignored); called before
        :meth:`Actuation.advance`."""
        for event in events:
            fault = event.fault
            if fault.kind not in _COMMAND_FAULTS and fault.kind not in _DRIVE_FAULTS:
                continue
            if event.action == CLEAR:
                self.faults.pop(fault.id, None)
                self._rng.pop(fault.id, None)
            else:
                self.faults[fault.id] = fault
                self._rng[fault.id] = fault_rng(self.seed, fault.id)
        if events:  # actuator rate limits: the active factors
            self._rate[:] = 1.0
            for fault in self.faults.values():
                if fault.kind == 'actuator_stuck':
                    self._rate[fault.index] = 0.0
                elif fault.kind == 'actuator_slow':
                    self._rate[fault.index] *= fault.param('factor')
            actuation.set_actuator_rate_factors(self._rate)
            np.multiply(self._nominal_dx, self._rate, out=self._dx)
            self._offsets = any(f.kind == 'actuator_offset' for f in self.faults.values())
            if self._offsets and self._offset_position is None:
                # the actuators are where they were driven at the end of the last step
                self._offset_position = actuation.actuator_position.copy()

    def filter_commands(self, commands: List[Command], step: int) -> List[Command]:
        """Return the commands that take effect at ``step``: the drained ones that no fault
        drops, ignores or delays, then delayed ones that are due (stamped with ``step``)."""
        due = self._delayed.pop(step, [])
        if not self.faults:
            return commands + [_at(c, step) for c in due] if due else commands
        out = []
        for command in commands:
            delay = 0
            lost = False
            for fault in self.faults.values():
                kind = fault.kind
                if kind in ('command_drop', 'command_delay'):
                    if _TOPIC_KIND[fault.target] != command.kind:
                        continue
                    if kind == 'command_drop':
                        lost |= bool(self._rng[fault.id].random() < fault.param('probability'))
                    else:
                        delay = max(delay, steps_of(fault.param('delay'), self.dt))
                elif (kind.startswith('belt_') and command.kind == BELT
                      or kind.startswith('actuator_') and command.kind == ACTUATOR) \
                        and fault.index == command.index:
                    if kind.endswith('_ignore_commands'):
                        lost = True
                    elif kind.endswith('_delay_commands'):
                        delay = max(delay, steps_of(fault.param('delay'), self.dt))
            if lost:
                self.dropped += 1
            elif delay:
                self.delayed += 1
                self._delayed.setdefault(step + delay, []).append(command)
            else:
                out.append(command)
        return out + [_at(c, step) for c in due]

    def drive(self, actuation: Actuation) -> Tuple[np.ndarray, np.ndarray]:
        """Return the belt speeds [m/s] and actuator positions the stages get this step (after
        :meth:`Actuation.advance`); a stalled belt's drive is held at 0, an offset actuator
        moves toward where it is driven plus its offset (clipped to its range) at its speed."""
        belt = actuation.belt_speed.copy()
        position = actuation.actuator_position.copy()
        for fault in self.faults.values():
            kind = fault.kind
            if kind == 'belt_stall':
                actuation.belt_speed[fault.index] = 0.0
                belt[fault.index] = 0.0
        for fault in self.faults.values():
            kind = fault.kind
            if kind == 'belt_slip':
                belt[fault.index] *= fault.param('factor')
            elif kind == 'belt_speed_noise':
                belt[fault.index] += fault.param('sigma') * self._rng[fault.id].standard_normal()
        if self._offset_position is not None:
            position = self._offset(position)
        return belt, position

    def _offset(self, driven: np.ndarray) -> np.ndarray:
        """Move the offset positions one step toward ``driven`` plus the active offsets;
        return them (a copy), forgetting them once no offset is active and they are back on
        ``driven``."""
        goal = self._goal
        goal[:] = driven
        for fault in self.faults.values():
            if fault.kind == 'actuator_offset':
                i = fault.index
                goal[i] = min(max(driven[i] + fault.param('offset'), self._low[i]),
                              self._high[i])
        moved = self._offset_position
        ramp(moved, goal, self._dx)
        if not self._offsets and np.array_equal(moved, driven):
            self._offset_position = None
        return moved.copy()

    def reset(self) -> None:
        """Forget every fault and delayed command (counters are kept)."""
        self.faults.clear()
        self._rng.clear()
        self._delayed.clear()
        self._offset_position = None
        self._offsets = False


def _at(command: Command, step: int) -> Command:
    return dataclasses.replace(command, step=step)
