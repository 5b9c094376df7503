"""Acting on a :class:`~conveyor_twin.testing.LockstepTwin` as a controller does: commands
(answered on ``command_status``) and the services ``spawn_parts``, ``reset``, ``inject_fault``
and ``clear_fault``.

Every argument is checked before anything is sent (:mod:`conveyor_twin.testing.checks`); the
twin's refusal comes back as the error its answer names.
"""

import os
from pathlib import Path
from typing import Any, Dict, Optional, Sequence, Union

from conveyor_twin_msgs.msg import ActuatorCommand, BeltCommand
import numpy as np

from conveyor_twin.cell import load_cell
from conveyor_twin.testing import checks
from conveyor_twin.testing.driver import CommandResult
from conveyor_twin.testing.errors import (CommandRejectedError, FaultRejectedError,
                                          ServiceError)
from conveyor_twin.testing.lifecycle import TwinLifecycle
from conveyor_twin.wire.fault_state import FaultEntry


class Acting(TwinLifecycle):
    """The commands and services part of :class:`~conveyor_twin.testing.LockstepTwin`."""

    def _command(self, msg: Union[BeltCommand, ActuatorCommand], check: bool,
                 what: str) -> CommandResult:
        driver = self._acting(what)
        with self._failing():
            result = driver.command(msg)
        if check and not result.accepted:
            raise CommandRejectedError(result.reason)
        return result

    def set_belt(self, belt: str, speed: float, *, check: bool = True) -> CommandResult:
        """Send ``belt_command`` and wait for the twin's answer; it takes effect at the next step.

        The command carries ``sender`` ``conveyor_twin_test`` and the next ``sequence`` number;
        the answer is the ``command_status`` that echoes both.

        :param belt: belt name
        :param speed: target speed along the belt [m/s] (any real number: the twin judges it)
        :param check: raise when the twin rejects it (else return the rejection)
        :raises ValueError: when ``speed`` is not a real number
        :raises CommandRejectedError: when rejected and ``check``; the message is the twin's
        """
        return self._command(BeltCommand(belt=name_arg('belt', belt),
                                         speed=checks.number('speed', speed)),
                             check, f'set_belt({belt!r})')

    def set_actuator(self, actuator: str, position: float, *,
                     check: bool = True) -> CommandResult:
        """Send ``actuator_command`` and wait for the twin's answer.

        :param actuator: actuator name
        :param position: target position [m] (linear) or [rad] (rotary); any real number
        :param check: raise when the twin rejects it (else return the rejection)
        :raises ValueError: when ``position`` is not a real number
        :raises CommandRejectedError: when rejected and ``check``
        """
        return self._command(ActuatorCommand(actuator=name_arg('actuator', actuator),
                                             position=checks.number('position', position)),
                             check, f'set_actuator({actuator!r})')

    def spawn(self, part_type: str, x: Sequence[float], y: Sequence[float],
              yaw: Optional[Sequence[float]] = None) -> np.ndarray:
        """Place parts now through ``spawn_parts``; return their ids.

        :param part_type: a part type of the cell
        :param x: positions [m]
        :param y: positions [m]
        :param yaw: headings [rad] (default: 0)
        :raises ValueError: when a pose is not a real number
        :raises ServiceError: when the twin refuses (the message is the twin's: an unknown
            type, a pose off the belts or outside the walls, an overlap)
        """
        x, y = checks.numbers_of('x', x), checks.numbers_of('y', y)
        yaw = [0.0] * len(x) if yaw is None else checks.numbers_of('yaw', yaw)
        driver = self._acting(f'spawn({part_type!r})')
        with self._failing():
            response = driver.spawn(name_arg('part_type', part_type), x, y, yaw)
        if not response.success:
            raise ServiceError(f'spawn_parts refused: {response.message}')
        return np.asarray(response.id, dtype=np.uint32)

    # -- faults --------------------------------------------------------------------------
    def inject_fault(self, kind: str, target: str = '', *, duration: float = 0.0,
                     part_type: str = '', **params: float) -> int:
        """Inject a fault through ``inject_fault``; it takes effect at the next step. Return
        its id.

        :param kind: a fault kind (``docs/faults.md``), e.g. ``barrier_stuck_blocked``
        :param target: what it acts on (barrier, belt, actuator, source, stream or command
            topic name; a part id); empty for ``parts_vanish``
        :param duration: clear it after this long [s]; 0: until cleared
        :param part_type: the part type ``source_wrong_type`` delivers
        :param params: the kind's parameters [SI], e.g. ``frequency=20.0``
        :raises ValueError: when ``duration`` or a parameter is not a real number
        :raises FaultRejectedError: when the twin refuses (the message is the twin's)
        """
        from conveyor_twin_msgs.srv import InjectFault
        duration = checks.number('duration', duration)
        values = [checks.number(f'parameter {k}', v) for k, v in params.items()]
        driver = self._acting(f'inject_fault({kind!r})')
        with self._failing():
            response = driver.inject_fault(InjectFault.Request(
                kind=name_arg('kind', kind), target=str(target), param_names=list(params),
                param_values=values, duration=duration,
                part_type=name_arg('part_type', part_type)))
        if not response.success:
            raise FaultRejectedError(response.message)
        return int(response.id)

    def clear_fault(self, fault_id: int) -> None:
        """Clear a fault through ``clear_fault``; it takes effect at the next step.

        :param fault_id: the id :meth:`inject_fault` returned (an integer in [0, 2**32 - 1])
        :raises FaultRejectedError: when no fault of that id is active
        """
        fault_id = checks.integer('fault_id', fault_id, 0, checks.UINT32_MAX)
        driver = self._acting(f'clear_fault({fault_id})')
        with self._failing():
            response = driver.clear_fault(fault_id)
        if not response.success:
            raise FaultRejectedError(response.message)

    def active_faults(self) -> Dict[int, FaultEntry]:
        """Return the active faults by id, as the ``faults`` stream stated them after the last
        step (a fault injected since takes effect at the next step)."""
        state = self._check_open('active_faults()').fault_state()
        return {} if state is None else {f.id: f for f in state.active}

    # -- reset ---------------------------------------------------------------------------
    def reset(self, *, seed: Optional[int] = None, cell_file: Union[None, str, Path] = None
              ) -> None:
        """Restart the twin at step 0 through ``reset``; forget every message received.

        :param seed: new seed (default: the current one; an integer in [0, 2**64 - 1])
        :param cell_file: another cell file with the same belts, actuators and barriers
        :raises ServiceError: when the twin refuses (the message is the twin's)
        """
        if seed is not None:
            seed = checks.integer('seed', seed, 0, checks.UINT64_MAX)
        driver = self._acting('reset()')
        with self._failing():
            driver.settle_edges()
            new_seed = self.seed if seed is None else seed
            response = driver.reset(new_seed, os.fspath(cell_file) if cell_file else '')
        if not response.success:
            raise ServiceError(f'reset refused: {response.message}')
        self.seed = new_seed
        if cell_file:
            self.cell = load_cell(cell_file)
        driver.forget()
        self._supervisor.forget_acks()
        self.step_index = self.time_ns = 0


def name_arg(what: str, value: Any) -> str:
    """Return ``value`` if it is a string (a name sent to the twin); else raise ValueError
    naming the argument."""
    if not isinstance(value, str):
        raise ValueError(f'{what} = {value!r} is not allowed: it must be a string')
    return value
