"""What the two scale nodes share: the split-layout coupling and the markers cadence."""

import time
from typing import Callable, Dict, Optional

from rclpy.node import Node
from std_msgs.msg import UInt8MultiArray

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell
from conveyor_twin.coord import codec
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.health import Health
from conveyor_twin.ros import coupling
from conveyor_twin.ros.params import declare_twin_parameters, DIAGNOSTICS_PERIOD_STEPS
from conveyor_twin.ros.qos import COUPLING_QOS, publish_failures, raw_publish

CONNECT_PERIOD = 0.01  # s between checks that the scale exchange is matched (split layout)
DONE_MATCH_TIMEOUT = 10.0  # s the first reply waits for its writer to see the coordinator


class ScaleNode(Node):
    """A node that owns a scale stage and publishes its streams after every step.

    Composed, the node publishes its part of the twin's frames (a sink of the shared output);
    split (``remote=True``), the node subscribes to the coupling topic, advances its own stage
    with each step input (:meth:`advance_remote`), publishes, and reports the step done
    (:meth:`finish_step`). Nodes that hand parts over to the other scale first exchange bytes
    with it and finish the step later (a state machine: no callback waits for another); they
    serve the coordinator only once that exchange is matched (:meth:`peers_matched`).

    :param stage: the scale's core wrapper (``advance``, ``reset``).
    :param role: :data:`~conveyor_twin.coord.codec.MICRO_ROLE` or
        :data:`~conveyor_twin.coord.codec.MACRO_ROLE`.
    :param counters: the part-balance counters the node reports (split layout; None: the
        stage's).
    :param reset: restarts the stage and whatever the assembly built with it (split layout;
        None: the stage's reset).
    :param markers_rate: MarkerArray rate [Hz]; 0 disables markers.
    :param health: where the node's own threads report a failure (composed: the twin's; a
        scale process: the process's); None: a health of the node's own.
    """

    def __init__(self, name: str, stage, role: int, *, context=None,
                 namespace: Optional[str] = None, remote: bool = False,
                 counters: Optional[Callable[[], Dict[str, float]]] = None,
                 reset: Optional[Callable[[Cell, int], None]] = None,
                 markers_rate: float = 30.0, step_s: float = 1e-3,
                 parameter_overrides=None, health: Optional[Health] = None) -> None:
        super().__init__(name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        self.health = health if health is not None else Health()
        self.stage = stage
        self.role = role
        self._stage_counters = counters or stage.counters
        self._reset = reset or stage.reset
        self.parameters = declare_twin_parameters(self, step_s=step_s)
        self.markers_every = (max(1, round(1.0 / (markers_rate * step_s)))
                              if markers_rate > 0 else 0)
        self.remote = remote
        if remote:
            self._done_pub = self.create_publisher(UInt8MultiArray, coupling.DONE_TOPIC,
                                                   COUPLING_QOS)
        self._connect_timer = None

    def serve_coordinator(self) -> None:
        """Split layout: subscribe to the coordinator's payloads, at once if this node has no
        exchange with the other scale node, else once it is matched (the coordinator waits for
        that subscription before its first step). Subclasses call it at the end of their
        constructor."""
        if not self.remote:
            return
        if self.peers_matched():
            self._subscribe_coordinator()
        else:
            self._connect_timer = self.create_timer(CONNECT_PERIOD, self._connect)

    def open_exchange(self, out_topic: str, in_topic: str, on_in) -> None:
        """Split layout, coupled cell: publish this node's hand-over bytes on ``out_topic``
        and take the other scale node's from ``in_topic`` with ``on_in`` (raw bytes)."""
        self.exchange_pub = self.create_publisher(UInt8MultiArray, out_topic, COUPLING_QOS)
        self.send_exchange = raw_publish(self.exchange_pub, self.get_logger())
        self._exchange_sub = self.create_subscription(UInt8MultiArray, in_topic, on_in,
                                                      COUPLING_QOS, raw=True)

    def peers_matched(self) -> bool:
        """Return True once the exchange with the other scale node (if any) is matched both
        ways: our writer sees its reader, our reader sees its writer."""
        return self.exchange_pub is None or (self.exchange_pub.get_subscription_count() >= 1
                                             and self._exchange_sub.get_publisher_count() >= 1)

    def _connect(self) -> None:
        if self._connect_timer.is_canceled() or not self.peers_matched():
            return
        self._connect_timer.cancel()  # (destroying a timer inside its own callback is unsafe)
        self._subscribe_coordinator()

    def _subscribe_coordinator(self) -> None:
        self.create_subscription(UInt8MultiArray, coupling.COUPLING_TOPIC,
                                 self._on_coupling, COUPLING_QOS, raw=True)

    def publish_step(self, inp: StepInput) -> None:
        """Split layout: build and publish this process's frame of the step just taken."""
        raise NotImplementedError

    def spawn_reply(self, body: bytes) -> bytes:
        """Place parts for a split-layout spawn request; return the reply bytes."""
        return b''

    def part_reply(self, body: bytes) -> bytes:
        """Answer a split-layout part query (``part_jam``); only the micro node holds parts."""
        return b''

    def advance_remote(self, inp: StepInput) -> None:
        """Advance the stage with the coordinator's step input, then :meth:`finish_step`;
        with an exchange, keep the step pending and :meth:`exchange` (the node finishes it
        when the other scale's bytes have arrived)."""
        self.stage.advance(inp)
        if self.exchange_pub is None:
            self.finish_step(inp)
            return
        self._pending = inp
        self.exchange(inp)

    def exchange(self, inp: StepInput) -> None:
        """Hand-over work of a pending step (coupled nodes override it)."""

    def finish_step(self, inp: StepInput) -> None:
        """Publish the step's streams and report the step done (with the stage's counters on
        the coordinator's diagnostics steps)."""
        self.publish_step(inp)
        reply = self._counters() if inp.step % DIAGNOSTICS_PERIOD_STEPS == 0 else b''
        if self.measure is not None:
            reply = codec.step_reply(reply, self.measure())
        self._report(inp.step, reply)

    def _counters(self) -> bytes:
        return codec.encode_counters(dict(self._stage_counters(),
                                          publish_failures=publish_failures(self)))

    def reset_stage(self, cell: Cell, seed: int) -> None:
        """Restart the stage (split layout reset); drop a pending step."""
        self._reset(cell, seed)
        self._pending = None

    def _report(self, step: int, reply: bytes = b'') -> None:
        self._last_step = step
        if not self._done_matched:
            self._done_matched = self._wait_done_matched()
        self._done_pub.publish(codec.to_cdr(codec.done(self.role, step, reply)))

    def _on_coupling(self, data: bytes) -> None:
        payload = codec.from_cdr(data)
        kind, body = payload[:1], payload[1:]
        if kind == codec.STEP:
            self.advance_remote(codec.unpack_step_input(body))
        elif kind == codec.RESET:
            seed, cell_file = codec.parse_reset(body)
            cell = load_cell(cell_file) if cell_file else self.stage.cell
            self.reset_stage(cell, seed)
            self._report(0)
        elif kind == codec.SPAWN:
            self._report(self._last_step, self.spawn_reply(body))
        elif kind == codec.COUNTERS:
            self._report(self._last_step, self._counters())
        elif kind == codec.PART_QUERY:
            self._report(self._last_step, self.part_reply(body))
        else:
            self.get_logger().error(f'unknown coupling payload {kind!r}; ignored')

    def _wait_done_matched(self) -> bool:
        """Wait until the reply writer has matched the coordinator's reader; return True if
        so. Discovery is not symmetric: the coordinator can see this node's writer (and send
        its first payload) before this writer sees the coordinator's reader, and a volatile
        reliable writer never delivers what it published before that match, so the first
        reply would be lost. Discovery runs in the middleware's threads: waiting here in a
        callback is safe."""
        deadline = time.monotonic() + DONE_MATCH_TIMEOUT
        while self._done_pub.get_subscription_count() < 1:
            if time.monotonic() > deadline:
                self.get_logger().warning('the coordinator does not see the step replies yet; '
                                          'replying anyway')
                return False
            time.sleep(0.005)
        return True

    _last_step = 0
    _done_matched = False
    #: Returns what a scenario's triggers need after every step (set when the coordinator arms
    #: a scenario with triggers on the cell's state; :meth:`AssembledTwin.trigger_measures`).
    measure: Optional[Callable[[], bytes]] = None
    exchange_pub = None  # the hand-over exchange's writer (split layout, coupled cells)
    _pending: Optional[StepInput] = None  # stepped, its hand-over not finished
