"""The lockstep handshake of a PLC: step the twin ``n`` steps on request.

OPC UA calls the method ``Step(n)``; Modbus increments the holding register ``Lockstep/Tick``
(modulo 65536), each increment asking for ``Lockstep/TickSteps`` steps, and reads
``Lockstep/DoneTick`` (equal to ``Tick`` once they are done). Both end in
:meth:`StepHandshake.request`, which steps the twin on the caller's thread (the twin's step
holds its lock, so requests from two servers are taken one after the other).
"""

import threading
from typing import Callable, Optional

from conveyor_twin.plc.tags import DEFAULT_TICK_STEPS
from conveyor_twin.plc.writes import WriteRejected

#: Modulus of ``Lockstep/Tick`` and ``Lockstep/DoneTick`` (uint16).
TICK_MODULUS = 65536


class StepHandshake:
    """Step the twin when a PLC asks, in lockstep mode only.

    :param step: advances the twin ``n`` steps (``runner.step``).
    :param mode_is_lockstep: the twin runs in lockstep (else every request is refused).
    :param max_steps: most steps one request may ask for.
    :param index: returns the twin's step index (``lambda: twin.step_index``); None: the steps
        taken through this handshake.
    """

    def __init__(self, step: Callable[[int], None], *, mode_is_lockstep: bool,
                 max_steps: int = 100_000, index: Optional[Callable[[], int]] = None) -> None:
        if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
            raise ValueError(f'StepHandshake: max_steps {max_steps!r}: expected an integer >= 1')
        self._step = step
        self.mode_is_lockstep = mode_is_lockstep
        self.max_steps = max_steps
        self._index = index
        self._lock = threading.Lock()
        self._busy = 0
        #: Steps taken through this handshake.
        self.steps = 0
        #: ``Lockstep/Tick`` as last written, ``Lockstep/DoneTick``, ``Lockstep/TickSteps``.
        self.tick = 0
        self.done_tick = 0
        self.tick_steps = DEFAULT_TICK_STEPS

    @property
    def done(self) -> bool:
        """True while no request is running (``Lockstep/Done``)."""
        return self._busy == 0

    def _check(self, n: object, what: str) -> int:
        if not self.mode_is_lockstep:
            raise WriteRejected('not_lockstep', f'{what}: the twin is not in lockstep mode '
                                '(start it with --mode lockstep)')
        if isinstance(n, bool) or not isinstance(n, int):
            raise WriteRejected('bad_type', f'{what}: {n!r} is not an integer')
        if not 1 <= n <= self.max_steps:
            raise WriteRejected('out_of_range', f'{what}: {n} steps is outside '
                                f'[1, {self.max_steps}]')
        return n

    def request(self, n: int) -> int:
        """Step the twin ``n`` steps now; return its step index after them.

        :raises WriteRejected: ``not_lockstep`` outside lockstep, ``bad_type`` or
            ``out_of_range`` for ``n`` not an integer in [1, max_steps]; nothing stepped.
        """
        n = self._check(n, f'step request of {n!r} steps')
        with self._lock:
            self._busy += 1
        try:
            self._step(n)
            with self._lock:
                self.steps += n
        finally:
            with self._lock:
                self._busy -= 1
        return int(self._index()) if self._index is not None else self.steps

    def set_tick_steps(self, n: int) -> None:
        """Set ``Lockstep/TickSteps``, the steps of one tick.

        :raises WriteRejected: as :meth:`request` for ``n``.
        """
        self.tick_steps = self._check(n, f'Lockstep/TickSteps {n!r}')

    def on_tick(self, tick: int) -> bool:
        """Take a write of ``Lockstep/Tick``: the next tick (last + 1 mod 65536) steps
        ``tick_steps`` steps and then sets ``done_tick``; the same tick again does nothing.

        :return: True if it stepped.
        :raises WriteRejected: ``out_of_range`` for any other value, or as :meth:`request`.
        """
        if isinstance(tick, bool) or not isinstance(tick, int) or not 0 <= tick < TICK_MODULUS:
            raise WriteRejected('bad_type', f'Lockstep/Tick {tick!r}: expected an integer in '
                                f'[0, {TICK_MODULUS - 1}]')
        if tick == self.tick:
            return False
        expected = (self.tick + 1) % TICK_MODULUS
        if tick != expected:
            raise WriteRejected('out_of_range', f'Lockstep/Tick {tick}: expected {expected} '
                                f'(the last tick {self.tick} + 1, modulo {TICK_MODULUS}) or '
                                f'{self.tick} again')
        self.request(self.tick_steps)
        self.tick = tick
        self.done_tick = tick
        return True
