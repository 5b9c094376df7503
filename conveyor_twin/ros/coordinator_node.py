"""``scale_coordinator``: owns time, takes commands and services, publishes clock and states.

Composed (``conveyor-twin run``), the scale stages live in the same process and are stepped
in memory; split (its own process), the twin's one stage is the scale processes
(:class:`~conveyor_twin.split.remote.RemoteStage`), so both layouts produce the same bytes. The
node itself never knows which: it takes the spawn, part check and counters of its layout.
"""

import time
from typing import Any, Callable, Dict, List, Optional

from builtin_interfaces.msg import Time
from conveyor_twin_msgs.msg import ActuatorCommand, BeltCommand
from conveyor_twin_msgs.srv import ClearFault, InjectFault, Reset, SpawnParts, Step
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rclpy.duration import Duration
from rclpy.node import Node

from conveyor_twin import contract
from conveyor_twin.coord.clock import stamp
from conveyor_twin.coord.commands import Command, CommandRejected
from conveyor_twin.coord.requests import (check_reset, check_spawn, RequestRejected,
                                          reset_message, SpawnRequest)
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.coord.twin import Twin
from conveyor_twin.faults.model import ActiveFault, FaultRejected, FaultSpec, no_such_part
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE, Failure
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import CoordinatorOutput
from conveyor_twin.ros.endpoints import create_publisher, create_service, create_subscription
from conveyor_twin.ros.params import declare_twin_parameters
from conveyor_twin.ros.qos import publish_failures
from conveyor_twin.ros.stream_publisher import StreamPublisher
from conveyor_twin.wire.diagnostics import encode_diagnostic_array, ERROR, OK, Status, WARN

#: The streams this node publishes from the frames.
STREAMS = contract.frame_streams(contract.Producer.COORDINATOR)

LOG_THROTTLE = 1.0                # s between two logged rejections
FINAL_DIAGNOSTICS_ACK = 2.0       # s the diagnostics after a failure may wait to be acked
#: Name of the diagnostics status of the twin's background threads and processes.
HEALTH_STATUS = 'conveyor_twin: health'


class CoordinatorNode(Node):
    """The coordinator's ROS face: commands in, clock/belt/actuator states and diagnostics out.

    :param twin: the coordinator core.
    :param runner: the stepping thread (realtime/fast) or the lockstep stepper.
    :param spawn: places a checked spawn request's parts now, returning their ids (the
        assembly's or the split coordinator role's spawn); raises ValueError if it placed none.
    :param holds_part: True if the micro scale holds a part of this id now (``part_jam``
        requests); raises TimeoutError or RuntimeError if it cannot tell.
    :param refresh: called after the ``step`` service stepped (split layout: fetches the scale
        nodes' counters of this state, for the summary).
    :param counters: returns part-balance counters for diagnostics and the summary.
    :param output: the twin's output whose frames this node publishes (composed: shared by the
        three nodes, attached to the twin by the assembly); None: the node makes the output of
        the coordinator's streams and attaches it to ``twin`` (split layout).
    """

    def __init__(self, twin: Twin, runner: Runner, *, context=None,
                 namespace: Optional[str] = None,
                 spawn: Callable[[SpawnRequest], np.ndarray],
                 holds_part: Callable[[int], bool],
                 counters: Optional[Callable[[], Dict[str, float]]] = None,
                 refresh: Optional[Callable[[], object]] = None,
                 parameter_overrides=None, output: Optional[TwinOutput] = None) -> None:
        super().__init__('scale_coordinator', context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        self.twin = twin
        self.runner = runner
        self.parameters = declare_twin_parameters(self, step_s=twin.cell.settings.step)
        self._spawn = spawn
        self._holds_part = holds_part
        self._refresh = refresh
        self._counter_sources: List[Callable[[], Dict[str, float]]] = (
            [counters] if counters else [])
        self._last_log = 0.0
        self._frame = twin.cell.settings.frame_id
        self.streams = StreamPublisher(self, STREAMS)
        self.clock_pub = self.streams.publishers[contract.CLOCK]
        self.belt_pub = self.streams.publishers[contract.BELT_STATES]
        self.actuator_pub = self.streams.publishers[contract.ACTUATOR_STATES]
        self.diag_pub = self.streams.publishers[contract.DIAGNOSTICS]
        #: One status per command received: accepted (level OK) or rejected (ERROR, with the
        #: reason), so a sender learns the outcome of each command it published.
        self.command_status_pub = create_publisher(self, contract.COMMAND_STATUS)
        create_subscription(self, contract.BELT_COMMAND, self._on_belt_command)
        create_subscription(self, contract.ACTUATOR_COMMAND, self._on_actuator_command)
        create_service(self, contract.STEP, self._on_step)
        create_service(self, contract.RESET, self._on_reset)
        create_service(self, contract.SPAWN_PARTS, self._on_spawn)
        create_service(self, contract.INJECT_FAULT, self._on_inject_fault)
        create_service(self, contract.CLEAR_FAULT, self._on_clear_fault)
        twin.step_listeners.append(self._log_faults)
        twin.health.listeners.append(self._log_failure)
        #: Called with (kind 'spawn' or 'reset', sim time before it [ns], the request) for every
        #: successful ``spawn_parts``/``reset`` call, under the twin's lock (the recorder).
        self.call_listeners: List[Callable[[str, int, Any], None]] = []
        if output is None:
            output = TwinOutput([CoordinatorOutput(twin, diagnostics=self.diagnostics_cdr)])
            twin.step_listeners.append(output.on_step)
            output.health = twin.health
        self.output = output
        output.subscribe(self.streams)

    # -- per step ------------------------------------------------------------------------
    def diagnostics_cdr(self, time_ns: int) -> bytes:
        """Return :meth:`diagnostics` as CDR bytes (the frame's ``diagnostics``), written from
        the statuses' strings without message objects (it runs on the stepping thread)."""
        return encode_diagnostic_array(time_ns, self._frame, self._statuses())

    def diagnostics(self, time_ns: int) -> DiagnosticArray:
        """Return step-time statistics, overruns, real-time factor, rejections, part balance."""
        msg = DiagnosticArray(status=[s if isinstance(s, DiagnosticStatus) else DiagnosticStatus(
            level=bytes([s.level]), name=s.name, message=s.message, hardware_id=s.hardware_id,
            values=[KeyValue(key=k, value=v) for k, v in s.values]) for s in self._statuses()])
        sec, nanosec = stamp(time_ns)
        msg.header.stamp = Time(sec=sec, nanosec=nanosec)
        msg.header.frame_id = self._frame
        return msg

    def _statuses(self) -> list:
        """The coordinator's status (a :class:`~conveyor_twin.wire.diagnostics.Status`), the
        faults' and the health's."""
        window = self.runner.stats.window()
        slowest = self.twin.step_parts.slowest() or {'total': 0.0, 'cpu': 0.0}
        values = {
            'step': str(self.twin.step_index),
            'mode': self.runner.mode.value,
            'step_time_mean_ms': f"{window['mean_ms']:.4f}",
            'step_time_p99_ms': f"{window['p99_ms']:.4f}",
            'step_time_max_ms': f"{window['max_ms']:.4f}",
            'overruns': str(self.runner.overruns),
            # the slowest step of the last one or two windows: its time per part, its CPU time
            'slowest_step_ms': f"{slowest['total']:.4f}",
            'slowest_step_parts_ms': self.twin.step_parts.describe(),
            'slowest_step_cpu_ms': f"{slowest['cpu']:.4f}",
            # realtime: how long after its deadline the stepping thread resumed at the latest
            # since the last diagnostics (a step that starts late can end late)
            'latest_wake_ms': f'{self.runner.pacer.take_latest_wake():.4f}',
            'real_time_factor': f'{self.runner.real_time_factor():.4f}',
            'realtime_priority': str(self.runner.priority),
            'rejected_commands': str(self.twin.commands.rejected_total),
            'last_rejection': self.twin.commands.last_rejection,
        }
        counters = self._counters()
        values['publish_failures'] = str(self.publish_failures(counters))
        values.update({k: f'{v:g}' if isinstance(v, float) else str(v)
                       for k, v in counters.items()})
        status = Status(
            WARN if self.runner.overruns else OK, 'conveyor_twin: scale_coordinator',
            f'{self.runner.overruns} overruns' if self.runner.overruns else 'running in time',
            self.twin.cell.settings.name, list(values.items()))
        actuators = self.twin.actuation.status()
        return [status, self._fault_status(), self._health_status()] + (
            [actuators] if actuators is not None else [])

    def _fault_status(self) -> DiagnosticStatus:
        """The faults' status: WARN naming every active fault, OK with none."""
        book = self.twin.faults
        active = sorted(book.active.values(), key=lambda f: f.id)
        values = {f'faults_{k}': str(v) for k, v in book.counters().items()}
        values['faults_last_rejection'] = book.last_rejection
        fa = self.twin.fault_actuation
        values['faults_commands_lost'] = str(fa.dropped)
        values['faults_commands_delayed'] = str(fa.delayed)
        return DiagnosticStatus(
            level=DiagnosticStatus.WARN if active else DiagnosticStatus.OK,
            name='conveyor_twin: faults', hardware_id=self.twin.cell.settings.name,
            message=(f'{len(active)} active: ' + ', '.join(_describe(f) for f in active)
                     if active else 'no active fault'),
            values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def _health_status(self) -> Status:
        """The background threads' and processes' status: OK, or ERROR naming each failure
        (one value per failure: name, error)."""
        health = self.twin.health
        if not health.failed:  # a plain attribute: nothing to lock while all is well
            return Status(OK, HEALTH_STATUS, health.status()[1], self.twin.cell.settings.name,
                          [('failures', '0')])
        failures = health.failures
        return Status(ERROR, HEALTH_STATUS, health.status()[1], self.twin.cell.settings.name,
                      [('failures', str(len(failures)))] + [(f.name, f.error) for f in failures])

    def _log_failure(self, failure: Failure) -> None:
        """Log a failure of a background thread or process once, at ERROR."""
        self.get_logger().error(f'{failure.describe()}; the run stops and exits with code '
                                f'{EXIT_BACKGROUND_FAILURE}')

    def publish_diagnostics(self, ack_timeout: float = FINAL_DIAGNOSTICS_ACK) -> bytes:
        """Publish the diagnostics now, off the step (after a failure: the ERROR status), hand
        them to the output's sinks (a recorder) and wait up to ``ack_timeout`` [s] until reliable
        subscribers acknowledged them. Call with the stepping stopped; return the CDR bytes."""
        time_ns = self.twin.time_ns
        data = self.diagnostics_cdr(time_ns)
        self.diag_pub.publish(data)
        self.output.emit(contract.DIAGNOSTICS, data, time_ns)
        self.diag_pub.wait_for_all_acked(Duration(nanoseconds=int(ack_timeout * 1e9)))
        return data

    def _log_faults(self, inp: StepInput, commands: List[Command]) -> None:
        """Log every fault injected or cleared (WARN), as it takes effect."""
        if not inp.faults:
            return
        for event in inp.faults:
            verb = 'injected' if event.action == 'inject' else f'cleared ({event.reason})'
            self.get_logger().warning(f'fault {verb} at step {event.step}: '
                                      f'{_describe(event.fault)}')

    # -- commands ------------------------------------------------------------------------
    def _counters(self) -> Dict[str, float]:
        out: Dict[str, float] = {}
        for source in self._counter_sources:
            out.update(source())
        return out

    def add_counters(self, source: Callable[[], Dict[str, float]]) -> None:
        """Add ``source``'s counters to the diagnostics and the summary (e.g. a viewer's)."""
        self._counter_sources.append(source)

    def report_rejected(self, exc: CommandRejected) -> None:
        """Log a rejected command (throttled); the command book has counted it."""
        self._rejected(exc)

    def _rejected(self, exc: CommandRejected) -> None:
        now = time.monotonic()
        if now - self._last_log >= LOG_THROTTLE:
            self._last_log = now
            self.get_logger().warning(
                f'{exc} (rejected, not applied; {self.twin.commands.rejected_total} so far)')

    def _report(self, topic: str, msg: Any, target: str, value: float,
                error: Optional[CommandRejected]) -> None:
        """Publish the outcome of one command on ``command_status`` (``step``: the step index
        when it arrived; an accepted command takes effect at the next step; ``sender`` and
        ``sequence``: as the command carried them, so its sender can tell its answers)."""
        step = self.twin.step_index
        status = DiagnosticStatus(
            level=DiagnosticStatus.ERROR if error else DiagnosticStatus.OK, name=topic,
            message=str(error) if error else 'accepted', hardware_id=target,
            values=[KeyValue(key='value', value=repr(float(value))),
                    KeyValue(key='step', value=str(step)),
                    KeyValue(key='sender', value=msg.sender),
                    KeyValue(key='sequence', value=str(msg.sequence))])
        self.command_status_pub.publish(status)

    def _on_belt_command(self, msg: BeltCommand) -> None:
        error = None
        try:
            self.twin.commands.submit_belt(msg.belt, msg.speed, msg.sender, msg.sequence)
        except CommandRejected as exc:
            error = exc
            self._rejected(exc)
        self._report(contract.BELT_COMMAND.name, msg, msg.belt, msg.speed, error)

    def _on_actuator_command(self, msg: ActuatorCommand) -> None:
        error = None
        try:
            self.twin.commands.submit_actuator(msg.actuator, msg.position, msg.sender,
                                               msg.sequence)
        except CommandRejected as exc:
            error = exc
            self._rejected(exc)
        self._report(contract.ACTUATOR_COMMAND.name, msg, msg.actuator, msg.position, error)

    # -- services ------------------------------------------------------------------------
    def _on_step(self, request: Step.Request, response: Step.Response) -> Step.Response:
        if self.runner.mode is TimeMode.LOCKSTEP:
            self.runner.step(int(request.steps))
            if self._refresh is not None:
                self._refresh()
        else:
            self.get_logger().warning(f'step service ignored in {self.runner.mode.value} mode')
        with self.twin.lock:
            response.step = self.twin.step_index
            sec, nanosec = stamp(self.twin.time_ns)
        response.stamp = Time(sec=sec, nanosec=nanosec)
        return response

    def reset_twin(self, request: Reset.Request) -> Reset.Response:
        """Serve a ``reset`` request as the service does (also for the simulation interfaces)."""
        return self._on_reset(request, Reset.Response())

    def spawn_parts(self, request: SpawnParts.Request) -> SpawnParts.Response:
        """Serve a ``spawn_parts`` request as the service does (also for the simulation
        interfaces)."""
        return self._on_spawn(request, SpawnParts.Response())

    def _on_reset(self, request: Reset.Request, response: Reset.Response) -> Reset.Response:
        try:
            cell = check_reset(self.twin.cell, request.cell_file)
        except RequestRejected as exc:
            response.success, response.message = False, str(exc)
            return response
        with self.twin.lock:
            before_ns = self.twin.time_ns
            self.twin.reset(cell, int(request.seed))  # the stages too (split: remote)
            self.runner.pacer.restart()
            for listener in self.call_listeners:
                listener('reset', before_ns, request)
        response.success = True
        response.message = reset_message(request.seed, cell)
        return response

    def _on_spawn(self, request: SpawnParts.Request,
                  response: SpawnParts.Response) -> SpawnParts.Response:
        try:
            spawn = check_spawn(self.twin.cell, request.part_type, request.x, request.y,
                                request.yaw)
            with self.twin.lock:
                ids = self._spawn(spawn)
                for listener in self.call_listeners:
                    listener('spawn', self.twin.time_ns, request)
        except ValueError as exc:  # RequestRejected, or placement refused
            response.success, response.message = False, str(exc)
            return response
        response.success = True
        response.message = spawn.placed_message()
        response.id = [int(i) for i in ids]
        return response

    def _on_inject_fault(self, request: InjectFault.Request,
                         response: InjectFault.Response) -> InjectFault.Response:
        names, values = list(request.param_names), list(request.param_values)
        try:
            if len(names) != len(values):
                raise self.twin.faults.reject(
                    f'{len(names)} param_names but {len(values)} param_values')
            spec = FaultSpec(request.kind, request.target, dict(zip(names, values)),
                             float(request.duration), request.part_type)
            with self.twin.lock:
                self._check_part_jam(self.twin.faults.validate(spec))
                fault = self.twin.faults.inject(spec)
        except FaultRejected as exc:
            response.success, response.message = False, f'rejected, nothing changed: {exc}'
            self.get_logger().warning(f'inject_fault {response.message}')
            return response
        response.success, response.id = True, fault.id
        response.message = f'fault {fault.id} takes effect at the next step'
        return response

    def _check_part_jam(self, fault: ActiveFault) -> None:
        """Reject a ``part_jam`` on a part id the micro scale does not hold now: composed, the
        micro stage of this process says; split, the micro node answers a part query over the
        coupling (as for a spawn)."""
        if fault.kind != 'part_jam' or fault.index < 0:
            return
        try:
            exists = self._holds_part(fault.index)
        except (TimeoutError, RuntimeError) as exc:
            raise self.twin.faults.reject(f"fault 'part_jam': the micro node did not say "
                                          f'whether part {fault.index} exists: {exc}')
        if not exists:
            raise self.twin.faults.reject(str(no_such_part(fault.index)))

    def _on_clear_fault(self, request: ClearFault.Request,
                        response: ClearFault.Response) -> ClearFault.Response:
        try:
            fault = self.twin.faults.clear(int(request.id))
        except FaultRejected as exc:
            response.success, response.message = False, f'rejected, nothing changed: {exc}'
            return response
        response.success = True
        response.message = f'fault {fault.id} ({fault.kind}) is cleared at the next step'
        return response

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
            # what failed in the background (only after a failure: the run then exits non-zero)
            **({'failures': self.twin.health.summary()} if self.twin.health.failed else {}),
        }


def _describe(fault: ActiveFault) -> str:
    """Return ``kind target (id N)`` of a fault, with its parameters."""
    params = ', '.join(f'{k}={v:g}' for k, v in fault.params)
    target = f' {fault.target}' if fault.target else ''
    return f'{fault.kind}{target}' + (f' [{params}]' if params else '') + f' (id {fault.id})'
