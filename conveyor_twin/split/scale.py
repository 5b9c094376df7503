"""A scale process's end of the split layout's protocol (no ROS imports).

:class:`ScaleRole` takes every payload the coordinator sends (:meth:`ScaleRole.on_coupling`:
step, reset, spawn, counters, part query), advances its stage with each step input, builds the
process's frame (its own :class:`~conveyor_twin.output.hub.TwinOutput`, whose sinks publish it)
and answers ``done``. Roles that hand parts over to the other scale
(:mod:`conveyor_twin.split.roles`) first exchange bytes with it and finish the step when the
other side's bytes arrive (:meth:`ScaleRole.on_exchange`; a state machine: nothing waits).

The bytes go through a :class:`ScaleLink` of the ROS side (``conveyor_twin.ros.scale_node``).
"""

from typing import Callable, Dict, Optional, Protocol

import numpy as np

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell
from conveyor_twin.contract import DIAGNOSTICS_PERIOD_STEPS
from conveyor_twin.coord.layout import Role
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.split import protocol


class ScaleLink(Protocol):
    """A scale process's end of the coupling topics (implemented in ``conveyor_twin.ros``)."""

    def send_done(self, data: bytes) -> None:
        """Publish CDR bytes of a ``done`` reply to the coordinator."""

    def send_exchange(self, data: bytes) -> None:
        """Publish CDR bytes of the hand-over to the other scale process."""

    def publish_failures(self) -> int:
        """Return the publishes the middleware refused so far (reported with the counters)."""

    def error(self, text: str) -> None:
        """Log a protocol error (the payload is ignored)."""


class ScaleRole:
    """The common part of the micro and macro processes of the split layout.

    :param role: :attr:`Role.MICRO` or :attr:`Role.MACRO`.
    :param stage: the scale's stage (``advance``, ``reset``, ``counters``, ``cell``).
    :param output: the process's output; its frame of a step is built when the step is done.
    :param exchanges: True if the role hands parts over to the other scale every step.
    """

    def __init__(self, role: Role, stage, output: TwinOutput, *, exchanges: bool) -> None:
        self.role = role
        self.stage = stage
        self.output = output
        self.exchanges = exchanges
        self.link: Optional[ScaleLink] = None
        #: Returns what a scenario's triggers need after every step (set when the coordinator
        #: arms a scenario with triggers on the cell's state, :meth:`trigger_measures`).
        self.measure: Optional[Callable[[], bytes]] = None
        self._last_step = 0
        self._pending: Optional[StepInput] = None  # stepped, its hand-over not finished

    @property
    def cell(self) -> Cell:
        """The cell the role runs now."""
        return self.stage.cell

    def serve(self, link: ScaleLink) -> None:
        """Send every reply and hand-over through ``link`` from now on."""
        self.link = link

    # -- from the coordinator ------------------------------------------------------------
    def on_coupling(self, data: bytes) -> None:
        """Take the CDR bytes of one coordinator payload and answer it."""
        payload = protocol.from_cdr(data)
        kind, body = payload[:1], payload[1:]
        if kind == protocol.STEP:
            self.advance(protocol.unpack_step_input(body))
        elif kind == protocol.RESET:
            seed, cell_file = protocol.parse_reset(body)
            self.reset(load_cell(cell_file) if cell_file else self.stage.cell, seed)
            self._report(0)
        elif kind == protocol.SPAWN:
            self._report(self._last_step, self.spawn_reply(body))
        elif kind == protocol.COUNTERS:
            self._report(self._last_step, self._counters())
        elif kind == protocol.PART_QUERY:
            self._report(self._last_step, self.part_reply(body))
        else:
            self.link.error(f'unknown coupling payload {kind!r}; ignored')

    def advance(self, inp: StepInput) -> None:
        """Advance the stage with the coordinator's step input, then :meth:`finish_step`;
        with an exchange, keep the step pending and :meth:`exchange` (the step finishes when
        the other scale's bytes have arrived)."""
        self.stage.advance(inp)
        if not self.exchanges:
            self.finish_step(inp)
            return
        self._pending = inp
        self.exchange(inp)

    def finish_step(self, inp: StepInput) -> None:
        """Build the step's frame (the output's sinks publish it) and report the step done
        (with the counters on the coordinator's diagnostics steps)."""
        self.output.on_step(inp)
        reply = self._counters() if inp.step % DIAGNOSTICS_PERIOD_STEPS == 0 else b''
        if self.measure is not None:
            reply = protocol.step_reply(reply, self.measure())
        loads = self.actuator_loads()
        if loads is not None:
            reply = protocol.with_loads(loads, reply)
        self._report(inp.step, reply)

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart the stage and whatever was built with it; drop a pending step."""
        self.stage.reset(cell, seed)
        self._pending = None

    def _counters(self) -> bytes:
        return protocol.encode_counters(dict(self.counters(),
                                             publish_failures=self.link.publish_failures()))

    def _report(self, step: int, reply: bytes = b'') -> None:
        self._last_step = step
        self.link.send_done(protocol.to_cdr(protocol.done(self.role, step, reply)))

    # -- what each role adds -------------------------------------------------------------
    def actuator_loads(self) -> Optional[np.ndarray]:
        """The step's load on every actuator [N] for the coordinator's stalls (None: not
        measured here)."""
        return None

    def counters(self) -> Dict[str, float]:
        """Part balance of the stage."""
        return self.stage.counters()

    def exchange(self, inp: StepInput) -> None:
        """Hand-over work of a pending step (roles with an exchange override it)."""

    def on_exchange(self, data: bytes) -> None:
        """Take the CDR bytes of the other scale process's hand-over (roles with an exchange
        override it)."""

    def spawn_reply(self, body: bytes) -> bytes:
        """Answer a spawn request; only the micro process places parts."""
        return b''

    def part_reply(self, body: bytes) -> bytes:
        """Answer a part query (``part_jam``); only the micro process holds parts."""
        return b''

    def trigger_measures(self) -> Callable[[], bytes]:
        """Return what this role sends after every step for a scenario's triggers."""
        raise NotImplementedError
