"""Errors of the test harness: each says what was asked and what the twin did instead."""


class TwinClosedError(RuntimeError):
    """The twin was used after :meth:`~conveyor_twin.testing.LockstepTwin.close`."""


class TwinTimeoutError(TimeoutError):
    """The twin (or a controller) did not answer within the harness's timeout [s]."""


class ConditionNotMet(AssertionError):
    """A step-until or wait-until condition did not hold within its step limit or timeout.

    An :class:`AssertionError`, so pytest reports it as a failed test with the message (what was
    waited for and the twin's state at the end).
    """


class CommandRejectedError(ValueError):
    """The twin rejected a command (unknown belt or actuator, not finite, out of range).

    :param reason: the twin's reason, as published on ``command_status``
    """

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class FaultRejectedError(ValueError):
    """The twin rejected a fault request (unknown kind or target, invalid parameter, unknown
    id); the message is the twin's reason. Nothing changed."""


class ServiceError(RuntimeError):
    """A ``spawn_parts`` or ``reset`` call failed; the message is the twin's."""
