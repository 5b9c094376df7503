"""Drive a running twin (composed in this process or split over processes) like a controller.

A :class:`Driver` owns a probe node and its own executor; it calls ``step`` in chunks and waits
until every stream of each chunk has been delivered, sends commands and waits for the twin's
answer on ``command_status`` (accepted, or rejected with the reason), and calls the
``spawn_parts`` and ``reset`` services. It knows nothing of the layout it talks to.
"""

from typing import Any, Callable, Dict, List, NamedTuple, Optional, Union

from conveyor_twin_msgs.msg import ActuatorCommand, BeltCommand
from conveyor_twin_msgs.srv import ClearFault, InjectFault, Reset, SpawnParts, Step
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.context import Context
from rclpy.executors import ShutdownException, SingleThreadedExecutor, TimeoutException
from rclpy.serialization import deserialize_message

from conveyor_twin import contract
from conveyor_twin.ros.qos import COMMAND_QOS
from conveyor_twin.ros.reader_handshake import HandshakeReader
from conveyor_twin.testing.errors import TwinTimeoutError
from conveyor_twin.testing.outages import EdgeAccount
from conveyor_twin.testing.probe import Probe, STREAMS
from conveyor_twin.testing.ros_env import wait_for
from conveyor_twin.wire import cdr
from conveyor_twin.wire.decoders import decode_fault_state
from conveyor_twin.wire.fault_state import FaultStateData

TIMEOUT = 60.0  # longest wait for one service answer, one chunk's streams or one command [s]
EVERY_STEP = tuple(t.name for t in (contract.PARTS, contract.LIGHT_BARRIERS,
                                      contract.BELT_STATES, contract.ACTUATOR_STATES))
HASHED = tuple(t.name for t in (contract.PARTS, contract.DENSITY, contract.LIGHT_BARRIERS,
                                contract.LIGHT_BARRIER_EDGES, contract.BELT_STATES,
                                contract.ACTUATOR_STATES))
LISTENED = tuple(STREAMS) + tuple(t.name for t in contract.REPLIES + contract.COMMANDS)
#: What the twin writes to a driver reliably: its writers must reach the driver's readers
#: before the first step (best-effort ``/clock`` may lose messages anyway).
REACHED = tuple(t for t in tuple(STREAMS) + tuple(t.name for t in contract.REPLIES)
                if t != contract.CLOCK.name)


class CommandResult(NamedTuple):
    """The twin's answer to one command.

    :param accepted: True when the command was valid (it takes effect at the next step)
    :param reason: why it was rejected ('' when accepted)
    :param step: the twin's step index when the command arrived
    """

    accepted: bool
    reason: str
    step: int


def command_result(status: DiagnosticStatus) -> CommandResult:
    """Return the :class:`CommandResult` a ``command_status`` message carries."""
    values = {kv.key: kv.value for kv in status.values}
    accepted = status.level == DiagnosticStatus.OK
    return CommandResult(accepted, '' if accepted else status.message,
                         int(values.get('step', -1)))


def command_origin(status: DiagnosticStatus) -> tuple:
    """Return (sender, sequence) a ``command_status`` message echoes ('' and 0 for a command
    sent without them)."""
    values = {kv.key: kv.value for kv in status.values}
    try:
        sequence = int(values.get('sequence', '0'))
    except ValueError:
        sequence = 0
    return values.get('sender', ''), sequence


def _nothing() -> None:
    """The default health check of a driver: nothing to check."""


class Driver:
    """A probe, clients and command publishers in one executor, against a twin's namespace.

    :param context: rclpy context
    :param density_per_step: density messages per step (one per macro zone of the cell)
    :param name: name of the probe node
    :param timeout: longest wait for one service answer, chunk of streams or command [s]
    """

    def __init__(self, context: Context, *, density_per_step: int = 0, name: str = 'probe',
                 timeout: float = TIMEOUT) -> None:
        self.density_per_step = density_per_step
        self.timeout = timeout
        #: The ``sender`` of the commands this driver sends (``command_status`` echoes it).
        self.sender = name
        self._sequence = 0
        #: Called while waiting: raises when a background thread or process of the twin (or a
        #: controller) failed, so a wait ends at once with the failure instead of a timeout.
        self.watch: Callable[[], None] = _nothing
        #: Called after every chunk: waits for paced controller processes (see the harness).
        self.after_chunk: Callable[[int], None] = lambda stamp_ns: None
        self._edges = EdgeAccount()
        self.probe = Probe(context, topics=LISTENED, name=name)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.probe)
        self.step_client = self.probe.create_client(Step, contract.STEP.name)
        self.spawn_client = self.probe.create_client(SpawnParts, contract.SPAWN_PARTS.name)
        self.reset_client = self.probe.create_client(Reset, contract.RESET.name)
        self._fault_state: tuple = (None, None)  # (latest faults message, decoded)
        self.inject_client = self.probe.create_client(InjectFault, contract.INJECT_FAULT.name)
        self.clear_client = self.probe.create_client(ClearFault, contract.CLEAR_FAULT.name)
        self.handshake = HandshakeReader(self.probe, [s.topic_name for s in self.probe._subs
                                                      if s.topic_name.lstrip('/') in REACHED])
        self.belt_pub = self.probe.create_publisher(BeltCommand, contract.BELT_COMMAND.name,
                                                   COMMAND_QOS)
        self.actuator_pub = self.probe.create_publisher(
            ActuatorCommand, contract.ACTUATOR_COMMAND.name, COMMAND_QOS)

    def wait_connected(self, timeout: Optional[float] = None) -> bool:
        """Wait until every stream, service and command topic of the twin is matched both
        ways, the twin's writers having answered the handshake
        (:mod:`conveyor_twin.ros.reader_handshake`), or :attr:`watch` raises: a process of the
        twin died."""
        return wait_for(lambda: self.watch() is None and self.probe.matched()
                        and self.step_client.service_is_ready()
                        and self.spawn_client.service_is_ready()
                        and self.reset_client.service_is_ready()
                        and self.inject_client.service_is_ready()
                        and self.belt_pub.get_subscription_count() > 0
                        and self.actuator_pub.get_subscription_count() > 0
                        and all(s.get_publisher_count() > 0 for s in self.probe._subs
                                if s.topic_name != contract.CLOCK.name)
                        and self.handshake.reached(),
                        self.timeout if timeout is None else timeout, self.executor)

    def wait(self, condition: Callable[[], bool], what: Union[str, Callable[[], str]],
             timeout: Optional[float] = None) -> None:
        """Spin until ``condition`` holds; raise :class:`TwinTimeoutError` naming ``what`` and
        the active stream outages (or the background failure :attr:`watch` raises)."""
        limit = self.timeout if timeout is None else timeout

        def watched() -> bool:
            self.watch()
            return condition()

        if not wait_for(watched, limit, self.executor):
            self.watch()
            what = what() if callable(what) else what
            raise TwinTimeoutError(f'{what}: not within {limit:g} s (messages so far: '
                                   f'{self.counts()}; {self.outages()})')

    def outages(self) -> str:
        """Name the active stream outages as the latest ``faults`` message states them."""
        timeline = self._edges.timeline
        timeline.update(self.probe.received[contract.FAULTS.name])
        return timeline.describe()

    def call(self, client: Any, request: Any) -> Any:
        """Call a service and return its response (bounded wait)."""
        future = client.call_async(request)
        self.wait(future.done, f'service {client.srv_name} did not answer')
        return future.result()

    def step(self, n: int, chunk: int = 50) -> Step.Response:
        """Advance n steps in calls of at most ``chunk``; after each, wait for every stream of
        those steps and for the twin's answer to every command seen so far."""
        response = None
        while n > 0:
            k = min(n, chunk)
            response = self.call(self.step_client, Step.Request(steps=k))
            want_ns = response.stamp.sec * 1_000_000_000 + response.stamp.nanosec
            self.wait(lambda: self._arrived(want_ns),
                      lambda: f'streams of steps up to {response.step} (t = {want_ns} ns; '
                              f'missing: {", ".join(self._missing(want_ns)) or "none"})')
            self.settle_commands()
            self.after_chunk(want_ns)
            n -= k
        return response

    def _missing(self, want_ns: int) -> List[str]:
        """Return the per-step streams that have no message of ``want_ns`` yet and are not
        silenced by a ``stream_outage`` fault (as the latest fault state says)."""
        received = self.probe.received
        silent = self.silenced()
        topics = EVERY_STEP + ((contract.DENSITY.name,) if self.density_per_step else ())
        # each stream comes from one writer, in order: its latest message is its newest step
        return [t for t in topics if t not in silent
                and (not received[t] or cdr.stamp_of(received[t][-1]) < want_ns)]

    def _arrived(self, want_ns: int) -> bool:
        """True once every per-step stream has a message of ``want_ns`` (streams silenced by
        a ``stream_outage`` fault, as the latest fault state says, are not waited for)."""
        return not self._missing(want_ns)

    def fault_state(self) -> Optional[FaultStateData]:
        """Return the latest ``faults`` message received, decoded (None before the first;
        decoded once per message, not on every poll of a wait)."""
        messages = self.probe.received[contract.FAULTS.name]
        if not messages:
            return None
        if self._fault_state[0] is not messages[-1]:
            self._fault_state = (messages[-1], decode_fault_state(messages[-1]))
        return self._fault_state[1]

    def silenced(self) -> set:
        """Return the streams a ``stream_outage`` fault silences, as the latest fault state
        says."""
        state = self.fault_state()
        if state is None:
            return set()
        return {f.target for f in state.active if f.kind == 'stream_outage'}

    def inject_fault(self, request: InjectFault.Request) -> InjectFault.Response:
        """Call ``inject_fault``; return its response."""
        return self.call(self.inject_client, request)

    def clear_fault(self, fault_id: int) -> ClearFault.Response:
        """Call ``clear_fault``; return its response."""
        return self.call(self.clear_client, ClearFault.Request(id=int(fault_id)))

    def drain(self, limit: int = 100_000) -> None:
        """Run every callback that is ready now, of the probe and of the nodes attached to the
        executor (a controller in this process reacts to what was delivered)."""
        for _ in range(limit):
            try:
                handler, _, _ = self.executor.wait_for_ready_callbacks(timeout_sec=0.0)
            except (TimeoutException, ShutdownException):
                return
            handler()
            exception = handler.exception()
            if exception is not None:
                raise exception

    def settle_commands(self) -> None:
        """Let attached nodes react, then wait until the twin answered every command seen on
        the command topics so far; repeat until no new command appears."""
        received = self.probe.received

        def sent() -> int:
            return sum(len(received[t.name]) for t in contract.COMMANDS)

        while True:
            self.drain()
            seen = sent()
            self.wait(lambda: len(received[contract.COMMAND_STATUS.name]) >= seen,
                      'answers on command_status to the commands sent')
            self.drain()
            if sent() == seen:
                return

    def counts(self) -> Dict[str, int]:
        """Messages received so far per topic."""
        return {t: len(v) for t, v in self.probe.received.items()}

    def forget(self) -> None:
        """Forget every message received (after a reset)."""
        for messages in self.probe.received.values():
            messages.clear()
        self._edges = EdgeAccount()
        self._fault_state = (None, None)

    def command(self, msg: Union[BeltCommand, ActuatorCommand]) -> CommandResult:
        """Publish a belt or actuator command with this driver's ``sender`` and the next
        ``sequence`` number, and wait for the twin's answer to it (matched by both)."""
        self._sequence = self._sequence % 0xFFFFFFFF + 1
        msg.sender, msg.sequence = self.sender, self._sequence
        if isinstance(msg, BeltCommand):
            publisher, what = self.belt_pub, f'belt_command {msg.belt!r} = {msg.speed!r}'
        else:
            publisher = self.actuator_pub
            what = f'actuator_command {msg.actuator!r} = {msg.position!r}'
        key = (msg.sender, msg.sequence)
        statuses = self.probe.received[contract.COMMAND_STATUS.name]
        seen = len(statuses)
        found: List[CommandResult] = []

        def answered() -> bool:
            nonlocal seen
            while seen < len(statuses):
                status = deserialize_message(statuses[seen], DiagnosticStatus)
                seen += 1
                if command_origin(status) == key:
                    found.append(command_result(status))
                    return True
            return False

        publisher.publish(msg)
        self.wait(answered, f'answer of the twin to {what} (sender {key[0]!r}, sequence '
                            f'{key[1]})')
        return found[0]

    def spawn(self, part_type: str, x: Any, y: Any, yaw: Any) -> SpawnParts.Response:
        """Place parts through the ``spawn_parts`` service; return its response."""
        return self.call(self.spawn_client, SpawnParts.Request(
            part_type=part_type, x=list(x), y=list(y), yaw=list(yaw)))

    def reset(self, seed: int, cell_file: str = '') -> Reset.Response:
        """Restart the twin through the ``reset`` service; return its response."""
        return self.call(self.reset_client, Reset.Request(cell_file=cell_file, seed=seed))

    def expected_edges(self) -> int:
        """Return the light-barrier edges published up to the latest barrier state received:
        the edges counted in steps when ``light_barrier_edges`` was not silenced."""
        received = self.probe.received
        return self._edges.expected(received[contract.LIGHT_BARRIERS.name],
                                    received[contract.FAULTS.name])

    def settle_edges(self) -> None:
        """Wait until every edge counted in the last barrier state and published (not
        silenced by a ``stream_outage``) has arrived."""
        received = self.probe.received
        if not received[contract.LIGHT_BARRIERS.name]:
            return
        edges = received[contract.LIGHT_BARRIER_EDGES.name]
        self.wait(lambda: len(edges) >= self.expected_edges(),
                  lambda: f'{self.expected_edges()} light-barrier edges counted and published '
                          f'({len(edges)} arrived)')

    def run(self, sequence: Any) -> None:
        """Play a sequence of ``('step', n)``, ``('command', msg)``, ``('spawn', args)``."""
        for kind, arg in sequence:
            if kind == 'step':
                self.step(arg)
            elif kind == 'command':
                result = self.command(arg)
                assert result.accepted, result.reason
            elif kind == 'spawn':
                response = self.spawn(*arg)
                assert response.success, response.message
            else:
                raise ValueError(f'unknown sequence item {kind!r}')
        self.settle_edges()

    def digests(self) -> Dict[str, str]:
        """SHA-256 of every hashed stream (everything but the best-effort /clock)."""
        return {t: self.probe.digest(t) for t in HASHED}

    def parameters(self, node_name: str) -> Dict[str, tuple]:
        """List, describe and get a node's parameters through its parameter services (as
        ``ros2 param dump``/``describe`` do); return ``{name: (value, description, read_only)}``.
        """
        from rclpy.parameter import parameter_value_to_python
        from rclpy.parameter_client import AsyncParameterClient

        client = AsyncParameterClient(self.probe, node_name)
        self.wait(client.services_are_ready, f'parameter services of {node_name}')

        def result(future: Any) -> Any:
            self.executor.spin_until_future_complete(future, timeout_sec=self.timeout)
            if not future.done():
                raise TwinTimeoutError(f'parameter service of {node_name} timed out')
            return future.result()

        names = list(result(client.list_parameters()).result.names)
        names = [n for n in names if n != 'use_sim_time']
        values = result(client.get_parameters(names)).values
        descriptors = result(client.describe_parameters(names)).descriptors
        return {n: (parameter_value_to_python(v), d.description, d.read_only)
                for n, v, d in zip(names, values, descriptors)}

    def close(self) -> None:
        """Destroy the probe and the executor."""
        self.executor.remove_node(self.probe)
        self.probe.destroy_node()
        self.executor.shutdown(timeout_sec=5.0)
