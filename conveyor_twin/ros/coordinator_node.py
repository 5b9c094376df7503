"""``scale_coordinator``: owns time, takes commands and services, publishes clock and states.

Composed (``conveyor-twin run``), the scale stages live in the same process and are stepped
in memory; split (its own process), every step's input goes to the ``micro_simulator`` and
``macro_simulator`` processes over hidden coupling topics and the coordinator waits for both to
report the step done before the next one, so both layouts produce the same bytes.
"""

import json
import threading
import time
from typing import Any, Callable, Dict, List, Optional

from builtin_interfaces.msg import Time
from conveyor_twin_msgs.msg import ActuatorCommand, ActuatorStates, BeltCommand, BeltStates
from conveyor_twin_msgs.srv import Reset, SpawnParts, Step
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import UInt8MultiArray

from conveyor_twin.cell import CellError, load_cell
from conveyor_twin.coord.clock import stamp
from conveyor_twin.coord.commands import Command, CommandRejected
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.coord.twin import Twin
from conveyor_twin.ros import coupling
from conveyor_twin.ros.params import declare_twin_parameters, DIAGNOSTICS_PERIOD_STEPS
from conveyor_twin.ros.qos import (CLOCK_QOS, COMMAND_QOS, COUPLING_QOS, publish_failures,
                                   raw_publish, SLOW_QOS, STREAM_QOS)
from conveyor_twin.wire import cdr

REMOTE_STEP_TIMEOUT = 10.0        # s a split scale node may take to report a step done
COUNTERS_TIMEOUT = 2.0            # s the split scale nodes may take to send their counters
LOG_THROTTLE = 1.0                # s between two logged rejections
COMMAND_STATUS_TOPIC = 'command_status'


class CoordinatorNode(Node):
    """The coordinator's ROS face: commands in, clock/belt/actuator states and diagnostics out.

    :param twin: the coordinator core.
    :param runner: the stepping thread (realtime/fast) or the lockstep stepper.
    :param remote_roles: in the split layout, the roles of the scale nodes to wait for each step.
    :param spawn: places parts now, returning their ids (composed: the micro stage's spawn).
    :param counters: returns part-balance counters for diagnostics and the summary.
    """

    def __init__(self, twin: Twin, runner: Runner, *, context=None,
                 namespace: Optional[str] = None,
                 remote_roles: tuple = (),
                 spawn: Optional[Callable] = None,
                 counters: Optional[Callable[[], Dict[str, float]]] = None,
                 parameter_overrides=None) -> None:
        super().__init__('scale_coordinator', context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        self.twin = twin
        self.runner = runner
        self.parameters = declare_twin_parameters(self, step_s=twin.cell.settings.step)
        self._spawn = spawn
        self._counters = counters or (lambda: {})
        self._last_log = 0.0
        cell = twin.cell
        self._frame = cell.settings.frame_id
        self._belt_states = cdr.BeltStatesEncoder(self._frame, [b.name for b in cell.belts])
        self._actuator_states = cdr.ActuatorStatesEncoder(
            self._frame, [a.name for a in cell.actuators])
        self.clock_pub = self.create_publisher(Clock, '/clock', CLOCK_QOS)
        self.belt_pub = self.create_publisher(BeltStates, 'belt_states', STREAM_QOS)
        self.actuator_pub = self.create_publisher(ActuatorStates, 'actuator_states', STREAM_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, 'diagnostics', SLOW_QOS)
        #: One status per command received: accepted (level OK) or rejected (ERROR, with the
        #: reason), so a sender learns the outcome of each command it published.
        self.command_status_pub = self.create_publisher(DiagnosticStatus, COMMAND_STATUS_TOPIC,
                                                        STREAM_QOS)
        self._pub_clock = raw_publish(self.clock_pub, self.get_logger())
        self._pub_belts = raw_publish(self.belt_pub, self.get_logger())
        self._pub_actuators = raw_publish(self.actuator_pub, self.get_logger())
        self.create_subscription(BeltCommand, 'belt_command', self._on_belt_command,
                                 COMMAND_QOS)
        self.create_subscription(ActuatorCommand, 'actuator_command',
                                 self._on_actuator_command, COMMAND_QOS)
        self.create_service(Step, 'step', self._on_step)
        self.create_service(Reset, 'reset', self._on_reset)
        self.create_service(SpawnParts, 'spawn_parts', self._on_spawn)
        self._remote_roles = tuple(remote_roles)
        #: Called with (kind 'spawn' or 'reset', sim time before it [ns], the request) for every
        #: successful ``spawn_parts``/``reset`` call, under the twin's lock (the recorder).
        self.call_listeners: List[Callable[[str, int, Any], None]] = []
        self._done: Dict[int, int] = {role: 0 for role in self._remote_roles}  # replies seen
        self._replies: Dict[int, tuple] = {}  # role -> (step, reply bytes) of the last reply
        self._step_replies: Dict[int, bytes] = {}  # role -> counters (reply bytes)
        self._replies_fresh = False  # _step_replies hold counters of the current state
        self._done_cv = threading.Condition()
        self._scales_ready = not self._remote_roles
        self.coupling_node: Optional[Node] = None
        if self._remote_roles:
            self.coupling_pub = self.create_publisher(UInt8MultiArray, coupling.COUPLING_TOPIC,
                                                      COUPLING_QOS)
            # The replies are served by a node of their own, spun by its own executor thread
            # (split.coordinator_main): a step/reset/spawn service callback of this node waits
            # for them, so they cannot share this node's executor.
            self.coupling_node = Node('_scale_coordinator_coupling', context=context,
                                      namespace=namespace, start_parameter_services=False)
            self._done_sub = self.coupling_node.create_subscription(
                UInt8MultiArray, coupling.DONE_TOPIC, self._on_done, COUPLING_QOS, raw=True)
            twin.step_listeners.append(self._step_remote)
        twin.step_listeners.append(self._publish_step)

    # -- per step ------------------------------------------------------------------------
    def _publish_step(self, inp: StepInput, commands: List[Command]) -> None:
        twin = self.twin
        self._pub_clock(cdr.encode_clock(inp.time_ns))
        self._pub_belts(self._belt_states.encode(
            inp.time_ns, twin.actuation.belt_target, inp.belt_speed))
        self._pub_actuators(self._actuator_states.encode(
            inp.time_ns, twin.actuation.actuator_target, inp.actuator_position))
        if inp.step % DIAGNOSTICS_PERIOD_STEPS == 0:
            self.diag_pub.publish(self.diagnostics(inp.time_ns))

    def diagnostics(self, time_ns: int) -> DiagnosticArray:
        """Return step-time statistics, overruns, real-time factor, rejections, part balance."""
        window = self.runner.stats.window()
        values = {
            'step': str(self.twin.step_index),
            'mode': self.runner.mode.value,
            'step_time_mean_ms': f"{window['mean_ms']:.4f}",
            'step_time_p99_ms': f"{window['p99_ms']:.4f}",
            'step_time_max_ms': f"{window['max_ms']:.4f}",
            'overruns': str(self.runner.overruns),
            'real_time_factor': f'{self.runner.real_time_factor():.4f}',
            'realtime_priority': str(self.runner.priority),
            'rejected_commands': str(self.twin.commands.rejected_total),
            'last_rejection': self.twin.commands.last_rejection,
        }
        counters = self._counters()
        values['publish_failures'] = str(self.publish_failures(counters))
        values.update({k: f'{v:g}' if isinstance(v, float) else str(v)
                       for k, v in counters.items()})
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if self.runner.overruns else DiagnosticStatus.OK,
            name='conveyor_twin: scale_coordinator', hardware_id=self.twin.cell.settings.name,
            message=(f'{self.runner.overruns} overruns' if self.runner.overruns
                     else 'running in time'),
            values=[KeyValue(key=k, value=v) for k, v in values.items()])
        sec, nanosec = stamp(time_ns)
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = Time(sec=sec, nanosec=nanosec)
        msg.header.frame_id = self._frame
        return msg

    # -- split layout --------------------------------------------------------------------
    def _on_done(self, data: bytes) -> None:
        role, step, reply = coupling.parse_done(coupling.from_cdr(data))
        with self._done_cv:
            if role in self._done:
                self._done[role] += 1
                self._replies[role] = (step, reply)
                self._done_cv.notify_all()

    def _send_and_wait(self, payload: bytes, step: int,
                       timeout: float = REMOTE_STEP_TIMEOUT) -> Dict[int, bytes]:
        """Send a coupling payload and wait for every scale node's reply to it [s]."""
        if not self._scales_ready and not self.wait_for_scales(REMOTE_STEP_TIMEOUT):
            raise TimeoutError('micro_simulator and macro_simulator are not connected')
        with self._done_cv:
            counts = dict(self._done)
        self.coupling_pub.publish(coupling.to_cdr(payload))
        deadline = time.monotonic() + timeout
        with self._done_cv:
            while any(self._done[r] <= counts[r] for r in counts):
                remaining = deadline - time.monotonic()
                if remaining <= 0 or not self.context.ok():
                    missing = [r for r in counts if self._done[r] <= counts[r]]
                    raise TimeoutError(f'scale nodes {missing} did not answer for step {step} '
                                       f'within {timeout:g} s')
                self._done_cv.wait(remaining)
            wrong = {r: v[0] for r, v in self._replies.items() if v[0] != step}
            if wrong:
                raise RuntimeError(f'scale nodes answered for other steps {wrong}, '
                                   f'expected {step}: the layout lost lockstep')
            return {r: v[1] for r, v in self._replies.items()}

    def _step_remote(self, inp: StepInput, commands: List[Command]) -> None:
        replies = self._send_and_wait(coupling.STEP + inp.pack(), inp.step)
        # the scale nodes send their counters on diagnostics steps only: keep the last ones
        self._replies_fresh = all(replies.get(r) for r in self._remote_roles)
        if self._replies_fresh:
            self._step_replies = replies

    def last_replies(self) -> Dict[int, bytes]:
        """Return each split scale node's counters (reply bytes, by role) for the current state:
        those of the last step if it carried them, else asked for now (if the nodes do not
        answer, e.g. stopped by the same Ctrl-C: those of the last diagnostics step)."""
        with self.twin.lock:
            if self._replies_fresh or not self._scales_ready:
                return self._step_replies
            try:
                self._step_replies = self._send_and_wait(
                    coupling.COUNTERS, self.twin.step_index, COUNTERS_TIMEOUT)
            except (TimeoutError, RuntimeError) as exc:
                self.get_logger().warning(f'scale node counters unavailable: {exc}')
                return self._step_replies
            self._replies_fresh = True
            return self._step_replies

    def wait_for_scales(self, timeout: float) -> bool:
        """Wait until every split scale node is connected both ways; return True if so."""
        if not self._remote_roles:
            return True
        deadline = time.monotonic() + timeout
        n = len(self._remote_roles)
        while time.monotonic() < deadline:
            # matched both ways: our writer sees their readers, our reader sees their writers
            if (self.coupling_pub.get_subscription_count() >= n
                    and self._done_sub.get_publisher_count() >= n):
                self._scales_ready = True
                return True
            time.sleep(0.01)
        return False

    # -- commands ------------------------------------------------------------------------
    def _rejected(self, exc: CommandRejected) -> None:
        now = time.monotonic()
        if now - self._last_log >= LOG_THROTTLE:
            self._last_log = now
            self.get_logger().warning(
                f'{exc} (rejected, not applied; {self.twin.commands.rejected_total} so far)')

    def _report(self, topic: str, target: str, value: float,
                error: Optional[CommandRejected]) -> None:
        """Publish the outcome of one command on ``command_status`` (``step``: the step index
        when it arrived; an accepted command takes effect at the next step)."""
        step = self.twin.step_index
        status = DiagnosticStatus(
            level=DiagnosticStatus.ERROR if error else DiagnosticStatus.OK, name=topic,
            message=str(error) if error else 'accepted', hardware_id=target,
            values=[KeyValue(key='value', value=repr(float(value))),
                    KeyValue(key='step', value=str(step))])
        self.command_status_pub.publish(status)

    def _on_belt_command(self, msg: BeltCommand) -> None:
        error = None
        try:
            self.twin.commands.submit_belt(msg.belt, msg.speed)
        except CommandRejected as exc:
            error = exc
            self._rejected(exc)
        self._report('belt_command', msg.belt, msg.speed, error)

    def _on_actuator_command(self, msg: ActuatorCommand) -> None:
        error = None
        try:
            self.twin.commands.submit_actuator(msg.actuator, msg.position)
        except CommandRejected as exc:
            error = exc
            self._rejected(exc)
        self._report('actuator_command', msg.actuator, msg.position, error)

    # -- services ------------------------------------------------------------------------
    def _on_step(self, request: Step.Request, response: Step.Response) -> Step.Response:
        if self.runner.mode is TimeMode.LOCKSTEP:
            self.runner.step(int(request.steps))
            if self._remote_roles:
                self.last_replies()  # the scale nodes' counters of this state, for the summary
        else:
            self.get_logger().warning(f'step service ignored in {self.runner.mode.value} mode')
        with self.twin.lock:
            response.step = self.twin.step_index
            sec, nanosec = stamp(self.twin.time_ns)
        response.stamp = Time(sec=sec, nanosec=nanosec)
        return response

    def _on_reset(self, request: Reset.Request, response: Reset.Response) -> Reset.Response:
        try:
            cell = load_cell(request.cell_file) if request.cell_file else self.twin.cell
        except CellError as exc:
            response.success, response.message = False, str(exc)
            return response
        if cell is not self.twin.cell and not _same_interface(cell, self.twin.cell):
            response.success = False
            response.message = ('reset to a cell with other belts, actuators or light barriers '
                                'needs a restart of the twin (the published arrays would change)')
            return response
        with self.twin.lock:
            before_ns = self.twin.time_ns
            self.twin.reset(cell, int(request.seed))
            self._replies_fresh = False
            if self._remote_roles:
                payload = coupling.RESET + int(request.seed).to_bytes(8, 'little') + \
                    (request.cell_file or '').encode()
                self._send_and_wait(payload, 0)
            self.runner.pacer.restart()
            for listener in self.call_listeners:
                listener('reset', before_ns, request)
        response.success = True
        response.message = f'reset to step 0 with seed {request.seed} ({cell.settings.name})'
        return response

    def _on_spawn(self, request: SpawnParts.Request,
                  response: SpawnParts.Response) -> SpawnParts.Response:
        cell = self.twin.cell
        n = len(request.x)
        try:
            type_index = cell.part_type_index(request.part_type)
        except KeyError:
            response.success = False
            response.message = (f'unknown part_type {request.part_type!r} (known: '
                                + ', '.join(p.name for p in cell.part_types) + ')')
            return response
        x, y = np.asarray(request.x, float), np.asarray(request.y, float)
        yaw = np.asarray(request.yaw, float) if len(request.yaw) else np.zeros(n)
        if not (len(request.y) == n and len(yaw) == n) or n == 0:
            response.success = False
            response.message = (f'x, y and yaw must have the same non-zero length '
                                f'(got {n}, {len(request.y)}, {len(request.yaw)})')
            return response
        if not (np.isfinite(x).all() and np.isfinite(y).all() and np.isfinite(yaw).all()):
            response.success, response.message = False, 'poses must be finite numbers'
            return response
        try:
            with self.twin.lock:
                if self._remote_roles:
                    self._replies_fresh = False
                    ids = self._spawn_remote(type_index, x, y, yaw)
                else:
                    ids = self._spawn(type_index, x, y, yaw)
                for listener in self.call_listeners:
                    listener('spawn', self.twin.time_ns, request)
        except ValueError as exc:
            response.success, response.message = False, str(exc)
            return response
        response.success = True
        response.message = f'placed {n} {request.part_type} part(s)'
        response.id = [int(i) for i in ids]
        return response

    def _spawn_remote(self, type_index: int, x, y, yaw) -> np.ndarray:
        payload = (coupling.SPAWN + int(type_index).to_bytes(2, 'little')
                   + np.ascontiguousarray(np.stack([x, y, yaw]), '<f8').tobytes())
        replies = self._send_and_wait(payload, self.twin.step_index)
        reply = replies.get(1, b'')
        if reply[:1] == b'E':
            raise ValueError(reply[1:].decode())
        return np.frombuffer(reply[1:], '<u4')

    def publish_failures(self, counters: Dict[str, float]) -> int:
        """Publishes refused by the middleware: this node's and the scale nodes' (counters
        ending in ``publish_failures``)."""
        return publish_failures(self) + int(sum(
            v for k, v in counters.items() if k.endswith('publish_failures')))

    def summary(self) -> dict:
        """Return the run's closing figures as a JSON-ready dict."""
        total = self.runner.stats.total()
        counters = self._counters()
        return {
            'cell': self.twin.cell.settings.name, 'seed': self.twin.seed,
            'mode': self.runner.mode.value, 'steps': self.twin.step_index,
            'sim_time_s': self.twin.time_ns * 1e-9,
            'step_time_ms': {k[:-3]: round(v, 4) for k, v in total.items()},
            'overruns': self.runner.overruns,
            'real_time_factor': round(self.runner.real_time_factor(), 4),
            'realtime_priority': self.runner.priority,
            'rejected_commands': self.twin.commands.rejected_total,
            'publish_failures': self.publish_failures(counters),
            **counters,
        }


def _same_interface(a, b) -> bool:
    def names(cell):
        return ([x.name for x in cell.belts], [x.name for x in cell.actuators],
                [x.name for x in cell.light_barriers], [z.name for z in cell.zones])
    return names(a) == names(b)


def summary_json(node: CoordinatorNode) -> str:
    """Return :meth:`CoordinatorNode.summary` as one line of JSON."""
    return json.dumps(node.summary(), sort_keys=True)


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``scale_coordinator`` as its own process (console script; split layout)."""
    from conveyor_twin.ros.split import coordinator_main
    return coordinator_main(argv)
