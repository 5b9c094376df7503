"""Validated, step-stamped command queue.

Commands arrive from any thread (ROS callbacks); they are validated at once, and the valid ones
wait in a queue until the next step boundary, where :meth:`CommandBook.drain` stamps them with
the step at which they take effect. Invalid commands are never applied: they are counted per
reason and reported back to the caller.
"""

from collections import Counter, deque
from dataclasses import dataclass
import math
import threading
from typing import Deque, Dict, List, Tuple

from conveyor_twin.cell.model import Cell, Mode
from conveyor_twin.contract import ACTUATOR_COMMAND, BELT_COMMAND

# the command topics' names, as rejection texts start with them
BELT_TOPIC = BELT_COMMAND.name
ACTUATOR_TOPIC = ACTUATOR_COMMAND.name


class CommandKind(Mode):
    """What a command moves (a ``str`` Enum: members equal, print and record as their value)."""

    BELT = 'belt'          # value: target speed [m/s]
    ACTUATOR = 'actuator'  # value: target position [m or rad]


#: Largest ``sequence`` a command may carry (its wire type is uint32).
SEQUENCE_MAX = 2**32 - 1


@dataclass(frozen=True)
class Command:
    """A valid command. ``step`` is the step at which it takes effect (-1 while pending).

    :param kind: ``belt`` (value = target speed [m/s]) or ``actuator`` (value = target position,
        m or rad).
    :param index: index of the belt or actuator in the cell.
    :param sender: who sent it, as the command carried it (``''`` if it did not say).
    :param sequence: the sender's number of it (uint32; 0 if it did not say).
    """

    kind: CommandKind
    name: str
    index: int
    value: float
    step: int = -1
    sender: str = ''
    sequence: int = 0


class CommandRejected(ValueError):
    """A command failed validation; the message says why, ``reason`` is the counter's key
    (``'out_of_range'``, ``'not_finite'``, ``'unknown_belt'``, ...; '' if not counted)."""

    def __init__(self, message: str, reason: str = '') -> None:
        super().__init__(message)
        self.reason = reason


class CommandBook:
    """Validate commands against a cell, queue them, and stamp them at the step boundary."""

    def __init__(self, cell: Cell) -> None:
        self._belts: Dict[str, Tuple[int, float]] = {
            b.name: (i, b.max_speed) for i, b in enumerate(cell.belts)}
        self._actuators: Dict[str, Tuple[int, float, float, str]] = {
            a.name: (i, a.position_range[0], a.position_range[1], 'rad' if a.is_rotary else 'm')
            for i, a in enumerate(cell.actuators)}
        self._pending: Deque[Command] = deque()
        self._scheduled: Dict[int, List[Command]] = {}
        self._lock = threading.Lock()
        self.rejected: Counter = Counter()
        self.last_rejection = ''

    @property
    def rejected_total(self) -> int:
        """Number of commands rejected so far."""
        return sum(self.rejected.values())

    def reject(self, reason: str, message: str) -> CommandRejected:
        """Count a rejection under ``reason`` (e.g. from another command channel); return the
        error to report, with ``message``."""
        with self._lock:
            self.rejected[reason] += 1
            self.last_rejection = message
        return CommandRejected(message, reason)

    def _check_origin(self, topic: str, sender: str, sequence: int) -> None:
        if not isinstance(sender, str):
            raise self.reject('bad_origin', f'{topic}: sender {sender!r} is not a string')
        if isinstance(sequence, bool) or not isinstance(sequence, int) \
                or not 0 <= sequence <= SEQUENCE_MAX:
            raise self.reject('bad_origin', f'{topic}: sequence {sequence!r} is not an integer '
                              f'in [0, {SEQUENCE_MAX}]')

    def validate_belt(self, belt: str, speed: float, sender: str = '',
                      sequence: int = 0) -> Command:
        """Return the valid belt command (``speed`` [m/s]; ``sender`` and ``sequence`` as the
        command carried them) or raise :class:`CommandRejected`."""
        if belt not in self._belts:
            known = ', '.join(self._belts)
            raise self.reject('unknown_belt', f'{BELT_TOPIC}: unknown belt {belt!r} '
                               f'(known: {known})')
        index, max_speed = self._belts[belt]
        if not math.isfinite(speed):
            raise self.reject('not_finite', f'{BELT_TOPIC}: speed {speed!r} for belt {belt!r} '
                               'is not finite')
        if abs(speed) > max_speed:
            raise self.reject('out_of_range', f'{BELT_TOPIC}: speed {speed!r} m/s for belt '
                               f'{belt!r} is outside [{-max_speed:g}, {max_speed:g}] m/s')
        self._check_origin(BELT_TOPIC, sender, sequence)
        return Command(CommandKind.BELT, belt, index, float(speed), -1, sender, sequence)

    def validate_actuator(self, actuator: str, position: float, sender: str = '',
                          sequence: int = 0) -> Command:
        """Return the valid actuator command (``position`` [m or rad]; ``sender`` and
        ``sequence`` as the command carried them) or raise :class:`CommandRejected`."""
        if actuator not in self._actuators:
            known = ', '.join(self._actuators) or 'none'
            raise self.reject('unknown_actuator', f'{ACTUATOR_TOPIC}: unknown actuator '
                               f'{actuator!r} (known: {known})')
        index, low, high, unit = self._actuators[actuator]
        if not math.isfinite(position):
            raise self.reject('not_finite', f'{ACTUATOR_TOPIC}: position {position!r} for '
                               f'actuator {actuator!r} is not finite')
        if not low <= position <= high:
            raise self.reject('out_of_range', f'{ACTUATOR_TOPIC}: position {position!r} '
                               f'{unit} for actuator {actuator!r} is outside '
                               f'[{low:g}, {high:g}] {unit}')
        self._check_origin(ACTUATOR_TOPIC, sender, sequence)
        return Command(CommandKind.ACTUATOR, actuator, index, float(position), -1, sender, sequence)

    def submit(self, command: Command) -> None:
        """Queue a validated command for the next step boundary (thread-safe)."""
        self._pending.append(command)

    def submit_belt(self, belt: str, speed: float, sender: str = '',
                    sequence: int = 0) -> Command:
        """Validate and queue a belt command (``speed`` [m/s], from ``sender`` with its
        ``sequence`` number); raise :class:`CommandRejected` if invalid."""
        command = self.validate_belt(belt, speed, sender, sequence)
        self.submit(command)
        return command

    def submit_actuator(self, actuator: str, position: float, sender: str = '',
                        sequence: int = 0) -> Command:
        """Validate and queue an actuator command (``position`` [m or rad], from ``sender``
        with its ``sequence`` number); raise :class:`CommandRejected` if invalid."""
        command = self.validate_actuator(actuator, position, sender, sequence)
        self.submit(command)
        return command

    def schedule(self, step: int, command: Command) -> None:
        """Apply an already validated command exactly at ``step`` (re-simulation)."""
        self._scheduled.setdefault(step, []).append(command)

    def drain(self, step: int) -> List[Command]:
        """Return the commands that take effect at ``step``, stamped with it, in arrival order.

        Scheduled commands for this step come first, then the live queue.
        """
        out = [Command(c.kind, c.name, c.index, c.value, step, c.sender, c.sequence)
               for c in self._scheduled.pop(step, ())]
        pending = self._pending
        while pending:
            c = pending.popleft()
            out.append(Command(c.kind, c.name, c.index, c.value, step, c.sender, c.sequence))
        return out

    def clear(self) -> None:
        """Forget pending and scheduled commands (reset); counters are kept."""
        self._pending.clear()
        self._scheduled.clear()
