"""The scale processes of the split layout as one stage of the coordinator (no ROS imports).

:class:`RemoteStage` offers the coordinator core what the local stages offer
(:class:`~conveyor_twin.coord.stages.MicroStage`, :class:`~conveyor_twin.coord.stages.MacroStage`):
``advance(inp)``, ``reset(cell, seed)``, ``spawn``, ``counters``; each call sends one payload
of :mod:`conveyor_twin.split.protocol` to both scale processes over a :class:`Transport` and
waits for both ``done`` replies (matched by count and step). The transport is the ROS side's
(``conveyor_twin.ros.split``): it publishes bytes and hands every received reply to
:meth:`RemoteStage.on_reply`.
"""

import sys
import threading
import time
from typing import Callable, Dict, Iterable, List, Optional, Protocol, Set

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.layout import Role, SCALE_ROLES
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.health import process_alive
from conveyor_twin.split import protocol

REMOTE_STEP_TIMEOUT = 10.0        # s a split scale node may take to report a step done
COUNTERS_TIMEOUT = 2.0            # s the split scale nodes may take to send their counters
LIVENESS_PERIOD = 0.25            # s between checks that a silent scale node's process lives
CONNECT_POLL = 0.01               # s between two checks that the scale nodes are matched


class Transport(Protocol):
    """The coordinator's end of the coupling topics (implemented in ``conveyor_twin.ros``).

    It calls :attr:`receiver` with the CDR bytes of every reply that arrives (on a thread of
    its own, never the one waiting in :class:`RemoteStage`).
    """

    receiver: Callable[[bytes], None]

    def send(self, data: bytes) -> None:
        """Publish CDR bytes to every scale node."""

    def connected(self, peers: int) -> bool:
        """Return True once ``peers`` scale nodes are matched both ways (they see our payloads,
        we see their replies)."""

    def alive(self) -> bool:
        """Return False once the middleware shut down (no reply can come)."""

    def node_names(self) -> Set[str]:
        """Return the names of the nodes in the ROS graph (empty if unknown)."""


class ScaleNodeLost(RuntimeError):
    """A split scale node's process ended while the coordinator waited for its reply."""


class RemoteStage:
    """Both scale processes of the split layout behind the stage interface.

    :param cell: the validated cell (the scale processes loaded the same file).
    :param transport: the coupling topics; this stage becomes its :attr:`Transport.receiver`.
    :param pids: the process id of each scale role, if known (a reply that does not come then
        says whether that process still lives).
    """

    label = 'scale processes'   # its part of a step's time (both processes' steps)

    def __init__(self, cell: Cell, transport: Transport, *,
                 pids: Optional[Dict[Role, int]] = None) -> None:
        self.cell = cell
        self.transport = transport
        transport.receiver = self.on_reply
        self.roles = SCALE_ROLES
        self.pids: Dict[Role, int] = dict(pids or {})
        #: The scale nodes send measures for a scenario's triggers with every step reply.
        self.measures_wanted = False
        self._measures: Dict[int, bytes] = {}
        self._lock = threading.RLock()  # one exchange at a time
        self._step = 0  # the last step the scale processes took
        self._done: Dict[int, int] = {role: 0 for role in self.roles}  # replies seen
        self._replies: Dict[int, tuple] = {}  # role -> (step, reply bytes) of the last reply
        self._step_replies: Dict[int, bytes] = {}  # role -> counters (reply bytes)
        self._replies_fresh = False  # _step_replies hold counters of the current state
        self._done_cv = threading.Condition()
        self._loads: Optional[np.ndarray] = None
        self._ready = False
        #: Where a warning goes (the coordinator node passes its logger's).
        self.warn: Callable[[str], None] = _print_warning

    # -- the stage interface -------------------------------------------------------------
    def advance(self, inp: StepInput) -> None:
        """Send the step input to both scale processes; wait until both took the step."""
        with self._lock:
            replies = self._send_and_wait(protocol.step_payload(inp), inp.step)
            self._step = inp.step
            if Role.MICRO in replies:  # the actuator loads first
                replies[Role.MICRO], loads = protocol.split_loads(replies[Role.MICRO])
                self._loads = loads
            if self.measures_wanted:  # a scenario's triggers: the scale nodes' measures first
                for role, reply in replies.items():
                    replies[role], self._measures[role] = protocol.split_step_reply(reply)
            # the scale nodes send their counters on diagnostics steps only: keep the last ones
            self._replies_fresh = all(replies.get(r) for r in self.roles)
            if self._replies_fresh:
                self._step_replies = replies

    def actuator_load(self) -> Optional[np.ndarray]:
        """The load [N] on every actuator in the last step, as the micro process measured it
        (None before a step or without actuators)."""
        return self._loads

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart both scale processes with ``seed`` and ``cell`` (the current one, or the
        file it was loaded from)."""
        with self._lock:
            cell_file = '' if cell is self.cell else cell.source_file
            self._replies_fresh = False
            self._send_and_wait(protocol.reset_payload(seed, cell_file), 0)
            self.cell, self._step = cell, 0

    def spawn(self, part_type: int, x: np.ndarray, y: np.ndarray,
              yaw: np.ndarray) -> np.ndarray:
        """Place parts in the micro process now (all or nothing); return their ids.

        :raises ValueError: with the micro process's reason if nothing was placed.
        """
        with self._lock:
            self._replies_fresh = False
            replies = self._send_and_wait(protocol.spawn_payload(part_type, x, y, yaw),
                                          self._step)
            return protocol.parse_spawn_reply(replies.get(Role.MICRO, b''))

    def holds_part(self, part_id: int) -> bool:
        """Return True if the micro process holds a part ``part_id`` now.

        :raises TimeoutError, RuntimeError: if the micro process did not answer.
        """
        with self._lock:
            replies = self._send_and_wait(protocol.part_query_payload(part_id), self._step)
            return replies.get(Role.MICRO, b'') == b'Y'

    def counters(self) -> Dict[str, float]:
        """Part balance of both scale processes, keys prefixed ``micro_`` and ``macro_``: those
        of the last step if it carried them, else asked for now (if the nodes do not answer,
        e.g. stopped by the same Ctrl-C: those of the last diagnostics step)."""
        replies = self._replies_now()
        return {**protocol.decode_counters('micro', replies.get(Role.MICRO, b'')),
                **protocol.decode_counters('macro', replies.get(Role.MACRO, b''))}

    def _replies_now(self) -> Dict[int, bytes]:
        with self._lock:
            if self._replies_fresh or not self._ready:
                return self._step_replies
            try:
                self._step_replies = self._send_and_wait(protocol.COUNTERS, self._step,
                                                         COUNTERS_TIMEOUT)
            except (TimeoutError, RuntimeError) as exc:  # ScaleNodeLost is a RuntimeError
                self.warn(f'scale node counters unavailable: {exc}')
                return self._step_replies
            self._replies_fresh = True
            return self._step_replies

    # -- what the scale processes measured for a scenario's triggers ----------------------
    def measured_edge_count(self) -> np.ndarray:
        """Every light barrier's reported edge count after the last step, as the micro process
        measured it."""
        return protocol.decode_measures(self._measures[Role.MICRO])[0]

    def measured_zone_parts(self, index: int) -> float:
        """The parts in zone ``index`` after the last step: the micro process's bodies plus the
        macro process's density [parts]."""
        micro = protocol.decode_measures(self._measures[Role.MICRO])[1]
        macro = protocol.decode_measures(self._measures[Role.MACRO])[1]
        return float(micro[index]) + float(macro[index])

    # -- the exchange ----------------------------------------------------------------------
    def wait_connected(self, timeout: float) -> bool:
        """Wait up to ``timeout`` [s] until both scale nodes are matched both ways; return True
        if so."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.transport.connected(len(self.roles)):
                self._ready = True
                return True
            time.sleep(CONNECT_POLL)
        return False

    def on_reply(self, data: bytes) -> None:
        """Take the CDR bytes of a scale node's ``done`` reply (the transport's thread)."""
        role, step, reply = protocol.parse_done(protocol.from_cdr(data))
        with self._done_cv:
            if role in self._done:
                self._done[role] += 1
                self._replies[role] = (step, reply)
                self._done_cv.notify_all()

    def _send_and_wait(self, payload: bytes, step: int,
                       timeout: float = REMOTE_STEP_TIMEOUT) -> Dict[int, bytes]:
        """Send a payload and wait up to ``timeout`` [s] for every scale node's reply to it."""
        if not self._ready and not self.wait_connected(REMOTE_STEP_TIMEOUT):
            raise TimeoutError('micro_simulator and macro_simulator are not connected')
        with self._done_cv:
            counts = dict(self._done)
        self.transport.send(protocol.to_cdr(payload))
        deadline = time.monotonic() + timeout
        with self._done_cv:
            while any(self._done[r] <= counts[r] for r in counts):
                remaining = deadline - time.monotonic()
                missing = [r for r in counts if self._done[r] <= counts[r]]
                if remaining <= 0 or not self.transport.alive():
                    raise TimeoutError(f'{self.describe_silent(missing)} did not answer for '
                                       f'step {step} within {timeout:g} s')
                if not self._done_cv.wait(min(remaining, LIVENESS_PERIOD)):
                    gone = [r for r in missing
                            if r in self.pids and not process_alive(self.pids[r])]
                    if gone:  # no use waiting for a process that has ended
                        raise ScaleNodeLost(f'{self.describe_silent(gone)} did not answer '
                                            f'for step {step}')
            wrong = {r: v[0] for r, v in self._replies.items() if v[0] != step}
            if wrong:
                raise RuntimeError(f'scale nodes answered for other steps {wrong}, '
                                   f'expected {step}: the layout lost lockstep')
            return {r: v[1] for r, v in self._replies.items()}

    def describe_silent(self, roles: Iterable[int]) -> str:
        """Name each scale node of ``roles`` and say whether its process lives (by its process
        id if known, else whether the node is in the ROS graph)."""
        try:
            graph = self.transport.node_names()
        except Exception:  # noqa: BLE001 - a context shutting down has no graph
            graph = set()
        out: List[str] = []
        for role in roles:
            name = Role(role).node_name if role in self.roles else f'scale role {role}'
            pid = self.pids.get(role)
            if pid is not None:
                state = ('its process (pid %d) is alive' if process_alive(pid)
                         else 'its process (pid %d) has exited') % pid
            else:
                state = ('its node is in the ROS graph' if name in graph
                         else 'its node is not in the ROS graph')
            out.append(f'{name} ({state})')
        return ', '.join(out)


def _print_warning(text: str) -> None:
    print(f'scale_coordinator: {text}', file=sys.stderr, flush=True)
