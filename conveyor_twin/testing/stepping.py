"""Stepping a :class:`~conveyor_twin.testing.LockstepTwin` and waiting for conditions.

:class:`Stepping` advances the twin through the ``step`` service, ``chunk`` steps at a time,
waiting after each chunk for every stream and for the answers to every command, and steps or
waits until a condition over what the harness received holds.
"""

from typing import Callable, Optional

from conveyor_twin.testing import checks
from conveyor_twin.testing.errors import ConditionNotMet
from conveyor_twin.testing.reading import StreamReader
from conveyor_twin.testing.ros_env import wait_for


class Stepping(StreamReader):
    """The stepping and waiting part of :class:`~conveyor_twin.testing.LockstepTwin`."""

    def step(self, n: int = 1) -> int:
        """Advance ``n`` steps; return once every stream of them (and every edge) has reached
        the harness's subscribers and the twin has answered every command sent meanwhile.
        Streams silenced by a ``stream_outage`` fault (and the edges counted while
        ``light_barrier_edges`` is silenced) are not waited for.

        :param n: steps to take, an integer >= 0 (0: no step; the twin's health is checked)
        :return: the new step index
        :raises ValueError: for ``n`` not an integer >= 0
        :raises TwinClosedError: after :meth:`close`
        :raises TwinTimeoutError: when a stream or answer does not come in time; the message
            names what was waited for and the active stream outages
        :raises BackgroundFailure: when a background thread or process of the twin (or a
            started controller) failed
        """
        n = checks.integer('step(n): n', n, 0, None)
        driver = self._acting(f'step({n})')
        if n == 0:
            return self.step_index
        with self._failing():
            response = driver.step(n, chunk=self.chunk)
            driver.settle_edges()
            self._supervisor.check()
        self.step_index = int(response.step)
        self.time_ns = response.stamp.sec * 10**9 + response.stamp.nanosec
        return self.step_index

    def step_for(self, seconds: float) -> int:
        """Advance by ``seconds`` of simulation time, rounded to whole steps [s].

        :param seconds: a finite number >= 0 (less than half a step: no step)
        :raises ValueError: for a negative, infinite or NaN duration, or not a number
        """
        seconds = checks.seconds('step_for(seconds): seconds', seconds)
        return self.step(int(round(seconds / self.step_s)))

    def step_until(self, condition: Callable[[], bool], *, max_steps: int,
                   what: Optional[str] = None) -> int:
        """Step (``chunk`` steps at a time) until ``condition()`` holds; return the steps taken.

        The condition is checked after every chunk (so the streams it reads exist).

        :param condition: predicate over what the harness has received
        :param max_steps: the most steps to take (an integer >= 1)
        :param what: what is waited for, for the failure message (default: the condition)
        :return: steps taken (at least one chunk, at most ``max_steps``)
        :raises ConditionNotMet: when it does not hold after ``max_steps`` steps; the message
            names it and the twin's state at the end
        """
        max_steps = checks.integer('step_until: max_steps', max_steps, 1, None)
        if not callable(condition):
            raise ValueError(f'step_until: condition {condition!r} is not callable')
        self._acting('step_until()')
        taken = 0
        while taken < max_steps:
            k = min(self.chunk, max_steps - taken)
            self.step(k)
            taken += k
            if condition():
                return taken
        with self._failing():
            raise ConditionNotMet(
                f'{what or describe(condition)}: not met within {max_steps} steps '
                f'({max_steps * self.step_s:g} s); at the end: {self.describe_state()}')

    def wait_until(self, condition: Callable[[], bool], *, timeout: Optional[float] = None,
                   what: Optional[str] = None) -> None:
        """Serve callbacks without stepping until ``condition()`` holds (e.g. a controller in
        another process has answered).

        :param timeout: longest wait [s] (> 0; default: the harness's timeout)
        :raises ConditionNotMet: when it does not hold in time
        """
        timeout = checks.seconds('wait_until: timeout', timeout, open_low=True, optional=True)
        driver = self._acting('wait_until()')
        limit = driver.timeout if timeout is None else timeout
        with self._failing():
            if not wait_for(lambda: (self._supervisor.check(), condition())[1], limit,
                            driver.executor):
                raise ConditionNotMet(f'{what or describe(condition)}: not met within '
                                      f'{limit:g} s without stepping; at the end: '
                                      f'{self.describe_state()}'
                                      + self._supervisor.report())


def describe(condition: Callable[[], bool]) -> str:
    """Name a condition for a failure message: the first line of its docstring (a named
    function), else ``condition <name>``."""
    doc = (getattr(condition, '__doc__', None) or '').strip()
    name = getattr(condition, '__name__', repr(condition))
    return doc.splitlines()[0] if doc and name != '<lambda>' else f'condition {name}'
