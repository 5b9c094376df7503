"""A PLC's writes as commands: validated like ``belt_command`` and ``actuator_command``.

A write of a belt's ``SpeedSetpoint`` or an actuator's ``Target`` becomes a
:class:`~conveyor_twin.coord.commands.Command` validated and queued by the twin's
:class:`~conveyor_twin.coord.commands.CommandBook`: it takes effect at the next step, is
recorded and re-simulates like any command, with ``sender`` naming the protocol and
``sequence`` counting the writer's accepted and rejected writes. A rejected write is never
applied: it raises :class:`WriteRejected` and is counted in ``book.rejected`` under its reason.
"""

import numbers
import threading

import numpy as np

from conveyor_twin.coord.commands import Command, CommandBook, CommandRejected, SEQUENCE_MAX
from conveyor_twin.plc.tags import float32_value, Tag

#: Reasons of :class:`WriteRejected` besides the command book's (``out_of_range``,
#: ``not_finite``, ``unknown_belt``, ``unknown_actuator``).
WRITE_REASONS = ('bad_type', 'read_only', 'not_writable', 'not_lockstep')


class WriteRejected(ValueError):
    """A PLC write or step request that was refused; nothing was applied.

    :param reason: ``'out_of_range'``, ``'not_finite'``, ``'bad_type'``, ``'read_only'``,
        ``'not_writable'``, ``'not_lockstep'``, ``'unknown_belt'``, ``'unknown_actuator'``.
    :param message: what was refused and why, naming the tag, the value and the allowed range.
    """

    def __init__(self, reason: str, message: str) -> None:
        super().__init__(message)
        self.reason = reason
        self.message = message


class PlcWriter:
    """Turn PLC writes into validated, queued commands of ``book``.

    :param book: the twin's command book (``twin.commands``).
    :param sender: the commands' sender (``'opcua'``, ``'modbus'``).
    :param read_only: refuse every write (reason ``read_only``).
    """

    def __init__(self, book: CommandBook, *, sender: str, read_only: bool = False) -> None:
        self.book = book
        self.sender = sender
        self.read_only = read_only
        self.accepted = 0
        self.rejected = 0
        self._sequence = 0
        self._lock = threading.Lock()

    def _next_sequence(self) -> int:
        with self._lock:
            self._sequence = self._sequence % SEQUENCE_MAX + 1
            return self._sequence

    def _reject(self, reason: str, message: str) -> WriteRejected:
        self.book.reject(reason, message)
        with self._lock:
            self.rejected += 1
        return WriteRejected(reason, message)

    def write(self, tag: Tag, value: object, *, client: str = '') -> Command:
        """Validate ``value`` for ``tag`` and queue it for the next step; return the command.

        :param value: a real number (int or float, not bool): the target speed [m/s] or
            position [m or rad]; a numpy float32 counts as its shortest decimal
            (:func:`~conveyor_twin.plc.tags.float32_value`).
        :param client: the writing client (e.g. its address), appended to the sender.
        :raises WriteRejected: nothing applied; counted in ``book.rejected``.
        """
        where = f'{self.sender} write of {tag.path!r}'
        kind = tag.source[0] if tag.source else ''
        if not tag.writable or kind not in ('belt', 'actuator'):
            raise self._reject('not_writable', f'{where}: the tag is not writable (writable: '
                               'Belts/*/SpeedSetpoint, Actuators/*/Target)')
        if self.read_only:
            raise self._reject('read_only', f'{where}: the PLC interface is read-only')
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise self._reject('bad_type', f'{where}: value {value!r} of type '
                               f'{type(value).__name__} is not a number')
        try:
            value = float32_value(value) if isinstance(value, np.float32) else float(value)
        except (OverflowError, ValueError):
            raise self._reject('out_of_range', f'{where}: value {value!r} is outside the '
                               'range of a float') from None
        sender = f'{self.sender} {client}' if client else self.sender
        sequence = self._next_sequence()
        try:
            validate = self.book.validate_belt if kind == 'belt' else \
                self.book.validate_actuator
            command = validate(tag.target, value, sender, sequence)
        except CommandRejected as exc:  # counted by the book
            with self._lock:
                self.rejected += 1
            raise WriteRejected(exc.reason or 'rejected', f'{where}: {exc}') from None
        self.book.submit(command)
        with self._lock:
            self.accepted += 1
        return command
