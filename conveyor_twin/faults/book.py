"""The coordinator's book of faults: requests in, one tuple of events per step out.

Requests arrive from any thread (a ROS service, the testing API) or are scheduled at a step (a
scenario, a re-simulation). :meth:`FaultBook.take` runs at the start of every step, under the
twin's lock: it turns the requests that are due into :class:`FaultEvent` objects stamped with
the step, adds the clears of faults whose duration is over, and updates the active set. The
events travel with the step's input to every stage (and, split, to the other processes), so
every process applies the same faults from the same step on.
"""

from dataclasses import dataclass
import threading
from typing import Dict, List, Optional, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.faults.model import ActiveFault, FaultRejected, FaultSpec, validate

INJECT = 'inject'
CLEAR = 'clear'


@dataclass(frozen=True)
class FaultEvent:
    """A fault injected or cleared, in effect from ``step`` on.

    :param action: ``inject`` or ``clear``.
    :param reason: why: ``request`` (service, API), ``scenario``, ``expired``, or the trigger
        that fired.
    """

    step: int
    action: str
    fault: ActiveFault
    reason: str = 'request'

    def as_dict(self) -> dict:
        """Return the event as plain data."""
        return {'step': self.step, 'action': self.action, 'fault': self.fault.as_dict(),
                'reason': self.reason}

    @classmethod
    def from_dict(cls, data: dict) -> 'FaultEvent':
        """Rebuild an event from :meth:`as_dict`."""
        return cls(int(data['step']), data['action'], ActiveFault.from_dict(data['fault']),
                   data.get('reason', 'request'))


def fault_rng(seed: int, fault_id: int) -> np.random.Generator:
    """Return the random stream of one fault of a run (noise, drops, chatter phase)."""
    return np.random.Generator(np.random.PCG64([int(seed) & 0xFFFFFFFF, int(fault_id), 0xFA17]))


def steps_of(seconds: float, dt: float) -> int:
    """Return a duration in whole steps, at least one [1]."""
    return max(1, int(round(seconds / dt)))


class FaultBook:
    """Validated fault requests, the active faults and their counters.

    :param cell: the cell faults are validated against.
    """

    def __init__(self, cell: Cell) -> None:
        self._lock = threading.Lock()
        self.injected = 0
        self.cleared = 0
        self.expired = 0
        self.rejected = 0
        self.last_rejection = ''
        self.load(cell)

    def load(self, cell: Cell) -> None:
        """Forget every fault and request (reset); ids start again at 1, counters are kept."""
        with self._lock:
            self.cell = cell
            self.dt = cell.settings.step
            self.active: Dict[int, ActiveFault] = {}
            self._next_id = 1
            self._live: List[Tuple[str, ActiveFault, str]] = []
            self._scheduled: Dict[int, List[Tuple[str, ActiveFault, str]]] = {}
            self._expiry: Dict[int, List[int]] = {}
            self._pending_ids: Dict[int, ActiveFault] = {}
            self._canceled: set = set()  # ids cleared before their injection
            #: Incremented whenever the active set changes (the ``faults`` stream is sent then).
            self.version = 0

    # -- requests ------------------------------------------------------------------------
    def _reject(self, exc: FaultRejected) -> FaultRejected:
        self.rejected += 1
        self.last_rejection = str(exc)
        return exc

    def reject(self, message: str) -> FaultRejected:
        """Count a request refused elsewhere (a malformed service call); return the error."""
        with self._lock:
            return self._reject(FaultRejected(message))

    def validate(self, spec: FaultSpec) -> ActiveFault:
        """Return the fault ``spec`` would become, with the next id, without injecting it.

        :raises FaultRejected: if the request is invalid (counted).
        """
        with self._lock:
            try:
                return validate(self.cell, spec, self._next_id)
            except FaultRejected as exc:
                raise self._reject(exc) from None

    def inject(self, spec: FaultSpec, *, step: Optional[int] = None,
               reason: str = 'request') -> ActiveFault:
        """Validate ``spec`` and inject it at the next step (or at ``step``); return it.

        :raises FaultRejected: if the request is invalid; nothing changes then.
        """
        with self._lock:
            try:
                fault = validate(self.cell, spec, self._next_id)
            except FaultRejected as exc:
                raise self._reject(exc) from None
            self._next_id += 1
            self._pending_ids[fault.id] = fault
            self._queue(step, (INJECT, fault, reason))
            return fault

    def clear(self, fault_id: int, *, step: Optional[int] = None,
              reason: str = 'request') -> ActiveFault:
        """Clear fault ``fault_id`` at the next step (or at ``step``); return it.

        :raises FaultRejected: if no fault of that id is active or waiting to be injected.
        """
        with self._lock:
            fault = self.active.get(fault_id) or self._pending_ids.get(fault_id)
            if fault is None:
                known = ', '.join(str(i) for i in sorted(self.active)) or 'none'
                raise self._reject(FaultRejected(f'no active fault with id {fault_id} '
                                                 f'(active: {known})'))
            self._queue(step, (CLEAR, fault, reason))
            return fault

    def schedule(self, event: FaultEvent) -> None:
        """Replay an event exactly at its step with its own id (re-simulation)."""
        with self._lock:
            if event.action == INJECT:
                self._next_id = max(self._next_id, event.fault.id + 1)
                self._pending_ids[event.fault.id] = event.fault
            self._queue(event.step, (event.action, event.fault, event.reason))

    def _queue(self, step: Optional[int], request: Tuple[str, ActiveFault, str]) -> None:
        if step is None:
            self._live.append(request)
        else:
            self._scheduled.setdefault(int(step), []).append(request)

    # -- per step ------------------------------------------------------------------------
    def take(self, step: int) -> Tuple[FaultEvent, ...]:
        """Return the events in effect from ``step`` on and apply them to the active set.

        Order: clears of expired faults, then scheduled requests, then live ones, each in
        request order. Cheap when nothing is due (the usual step).
        """
        if not (self._live or self._scheduled or self._expiry):
            return ()
        with self._lock:
            requests = [(CLEAR, self.active[i], 'expired') for i in self._expiry.pop(step, ())
                        if i in self.active]
            requests += self._scheduled.pop(step, [])
            requests += self._live
            self._live = []
            events = []
            for action, fault, reason in requests:
                if action == INJECT and fault.id in self._canceled:
                    self._canceled.discard(fault.id)
                    continue
                if action == INJECT:
                    self._pending_ids.pop(fault.id, None)
                    self.active[fault.id] = fault
                    self.injected += 1
                    if fault.duration > 0.0:
                        end = step + steps_of(fault.duration, self.dt)
                        self._expiry.setdefault(end, []).append(fault.id)
                elif fault.id in self.active:
                    del self.active[fault.id]
                    if reason == 'expired':
                        self.expired += 1
                    else:
                        self.cleared += 1
                else:  # not injected yet (its injection is skipped) or cleared twice
                    if self._pending_ids.pop(fault.id, None) is not None:
                        self._canceled.add(fault.id)
                        self.cleared += 1
                    continue
                events.append(FaultEvent(step, action, fault, reason))
            if events:
                self.version += 1
            return tuple(events)

    def counters(self) -> Dict[str, int]:
        """Return the counters: active, injected, cleared, expired, rejected."""
        return {'active': len(self.active), 'injected': self.injected,
                'cleared': self.cleared, 'expired': self.expired, 'rejected': self.rejected}
