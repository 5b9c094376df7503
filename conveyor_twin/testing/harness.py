"""A lockstep twin for tests: started in-process in a ROS domain of its own, driven over ROS.

:class:`LockstepTwin` starts the twin of a cell (composed in this process, or split over three
processes) in ``lockstep`` mode, in a private rclpy context on a domain id no other test holds
(loopback discovery only), and drives it the way a controller would: through the ``step``,
``spawn_parts`` and ``reset`` services, the command topics and the streams. Nothing it does
reads the twin's internals, so what a test sees is what a controller sees.
"""

import os
from pathlib import Path
import shutil
import subprocess
import tempfile
from typing import (Any, Callable, Dict, List, Mapping, NamedTuple, Optional, Sequence, Union)

from conveyor_twin_msgs.msg import (ActuatorCommand, ActuatorStates, BeltCommand, BeltStates,
                                    LightBarrierEdge)
from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell
from conveyor_twin.testing._layout import density_per_step, Layout, start_layout
from conveyor_twin.testing.driver import command_result, CommandResult, Driver, TIMEOUT
from conveyor_twin.testing.errors import (CommandRejectedError, ConditionNotMet,
                                          FaultRejectedError, ServiceError,
                                          TwinClosedError, TwinTimeoutError)
from conveyor_twin.testing.processes import RosProcesses
from conveyor_twin.testing.ros_env import DomainLease, lease_domain_id
from conveyor_twin.wire import cdr
from conveyor_twin.wire.fault_state import FaultEntry

DEFAULT_CHUNK = 10      # steps per ``step`` service call: a controller reacts within this many
DEFAULT_SEED = 0
PartStates = cdr.PartStatesData
DensityGrid = cdr.DensityGridData


class BeltState(NamedTuple):
    """A belt as ``belt_states`` last reported it: speeds [m/s]."""

    commanded_speed: float
    speed: float


class ActuatorState(NamedTuple):
    """An actuator as ``actuator_states`` last reported it: positions [m] or [rad]."""

    commanded_position: float
    position: float


class BeltSample(NamedTuple):
    """One belt in one ``belt_states`` message: its stamp [ns] and speeds [m/s]."""

    stamp_ns: int
    commanded: float
    actual: float


class BarrierState(NamedTuple):
    """A light barrier as ``light_barriers`` last reported it."""

    blocked: bool
    edge_count: int


class Edge(NamedTuple):
    """A light-barrier edge (``light_barrier_edges``).

    :param name: the barrier
    :param blocked: True when the beam became interrupted
    :param part_id: the part (0 for an edge of the macro scale)
    :param time_ns: interpolated simulation time of the edge [ns]
    :param step: the step during which it happened
    """

    name: str
    blocked: bool
    part_id: int
    time_ns: int
    step: int


class CommandRecord(NamedTuple):
    """A command the twin answered on ``command_status`` (from the harness or a controller).

    :param topic: ``belt_command`` or ``actuator_command``
    :param target: the belt or actuator named in the command
    :param value: commanded speed [m/s] or position [m] or [rad]
    :param result: accepted, or rejected with the reason
    """

    topic: str
    target: str
    value: float
    result: CommandResult


class LockstepTwin:
    """A twin in lockstep, started for a test; a context manager.

    :param cell: a cell file, a :class:`~conveyor_twin.cell.model.Cell`, or None for the
        embedded default cell
    :param seed: random seed of the run
    :param layout: ``composed`` (one process: this one) or ``split`` (three processes; needs a
        cell file or the default cell)
    :param chunk: steps per ``step`` service call; between calls the harness waits for every
        stream and for the twin's answer to every command, so an attached controller reacts
        within ``chunk`` steps
    :param timeout: longest wait for any one answer of the twin or a controller [s]
    :param foxglove: ``[HOST:]PORT`` to serve a live Foxglove view of the test's twin at (watch
        a test step by step); None: no view. Composed: port 0 picks a free one, see
        :attr:`foxglove`; split: the coordinator process serves it, give a port.
    :param scenario: a fault scenario file to arm (``docs/faults.md``); checked before the
        twin starts
    :raises ValueError: on an unknown layout, an invalid ``foxglove`` address, or port 0 with
        the split layout
    :raises conveyor_twin.faults.scenario.ScenarioError: on an invalid scenario file
    :raises conveyor_twin.viz.foxglove_view.FoxgloveError: if the view cannot listen there
    :raises conveyor_twin.cell.CellError: on an invalid cell file
    """

    def __init__(self, cell: Union[None, str, Path, Cell] = None, *, seed: int = DEFAULT_SEED,
                 layout: Layout = 'composed', chunk: int = DEFAULT_CHUNK,
                 timeout: float = TIMEOUT, foxglove: Optional[str] = None,
                 scenario: Union[None, str, Path] = None) -> None:
        if chunk < 1:
            raise ValueError(f'chunk must be at least 1 step (got {chunk})')
        if foxglove is not None:
            from conveyor_twin.viz.foxglove_view import FoxgloveError, parse_address
            try:
                _, port = parse_address(foxglove)
            except FoxgloveError as exc:
                raise ValueError(str(exc)) from None
            if port == 0 and layout == 'split':
                raise ValueError('foxglove: the split layout serves the view from its own '
                                 'process; give a port other than 0')
        cell_file = None if cell is None or isinstance(cell, Cell) else os.fspath(cell)
        self.cell: Cell = cell if isinstance(cell, Cell) else load_cell(cell_file)
        self.scenario = None
        if scenario is not None:
            from conveyor_twin.faults.scenario import load_scenario
            self.scenario = load_scenario(os.fspath(scenario), self.cell)
        self.seed = seed
        self.layout = layout
        self.chunk = chunk
        self.step_s = self.cell.settings.step
        self.step_index = 0
        #: Simulation time of the last step, as the ``step`` service answered it [ns].
        self.time_ns = 0
        self._closed = False
        self._nodes: List[Node] = []
        self._controllers: List[subprocess.Popen] = []
        self._log_dir = Path(tempfile.mkdtemp(prefix='conveyor_twin_test_'))
        self._lease: Optional[DomainLease] = lease_domain_id()
        self.domain_id = self._lease.domain_id
        self._processes = RosProcesses(domain_id=self.domain_id)
        self._running = None
        self._driver: Optional[Driver] = None
        # rcl reads the discovery range at init: nothing of this context leaves the machine.
        os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
        os.environ.pop('ROS_LOCALHOST_ONLY', None)
        os.environ.pop('ROS_STATIC_PEERS', None)
        self.context: Optional[Context] = None
        try:
            context = Context()
            rclpy.init(context=context, domain_id=self.domain_id,
                       signal_handler_options=SignalHandlerOptions.NO)
            self.context = context
            self._running = start_layout(self.cell, cell_file, seed=seed, layout=layout,
                                         context=self.context, domain_id=self.domain_id,
                                         foxglove=foxglove or '', scenario=self.scenario)
            self._driver = Driver(self.context, density_per_step=density_per_step(self.cell),
                                  name='conveyor_twin_test', timeout=timeout)
            if not self._driver.wait_connected():
                raise TwinTimeoutError(f'the {layout} twin was not discovered within '
                                       f'{timeout:g} s\n{self._running.logs()}')
        except BaseException:
            self.close()
            raise

    # -- life cycle ----------------------------------------------------------------------
    def __enter__(self) -> 'LockstepTwin':
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._closed

    def _check_open(self, what: str) -> Driver:
        if self._closed or self._driver is None:
            raise TwinClosedError(f'{what}: the twin is closed (used after close() or outside '
                                  'its with block)')
        return self._driver

    def close(self) -> None:
        """Stop controllers, attached nodes and the twin; release the domain. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._processes.stop_all()
            if self._driver is not None:
                for node in self._nodes:
                    self._driver.executor.remove_node(node)
                self._driver.close()
            for node in self._nodes:
                node.destroy_node()
            if self._running is not None:
                self._running.stop()
        finally:
            if self.context is not None:
                rclpy.try_shutdown(context=self.context)
            if self._lease is not None:
                self._lease.release()
            shutil.rmtree(self._log_dir, ignore_errors=True)

    @property
    def foxglove(self) -> Any:
        """The live :class:`~conveyor_twin.viz.foxglove_view.FoxgloveView` of a composed twin
        started with ``foxglove=`` (its ``port`` is where it listens), else None."""
        composed = self.composed
        return composed.foxglove if composed is not None else None

    @property
    def composed(self) -> Any:
        """The in-process twin of the composed layout (None when split), for white-box tests of
        the twin itself; not part of the stable API."""
        return self._running.composed if self._running is not None else None

    # -- time ----------------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulation time of the last step [s]."""
        return self.time_ns * 1e-9

    def step(self, n: int = 1) -> int:
        """Advance ``n`` steps; return once every stream of them (and every edge) has reached
        the harness's subscribers and the twin has answered every command sent meanwhile.

        :param n: steps to take (at least 1)
        :return: the new step index
        :raises TwinClosedError: after :meth:`close`
        """
        driver = self._check_open(f'step({n})')
        if n < 1:
            raise ValueError(f'step(n) takes at least 1 step (got {n})')
        response = driver.step(n, chunk=self.chunk)
        driver.settle_edges()
        self.step_index = int(response.step)
        self.time_ns = response.stamp.sec * 10**9 + response.stamp.nanosec
        return self.step_index

    def step_for(self, seconds: float) -> int:
        """Advance by ``seconds`` of simulation time (rounded to whole steps) [s]."""
        return self.step(max(1, round(seconds / self.step_s)))

    def step_until(self, condition: Callable[[], bool], *, max_steps: int,
                   what: Optional[str] = None) -> int:
        """Step (``chunk`` steps at a time) until ``condition()`` holds; return the steps taken.

        The condition is checked after every chunk (so the streams it reads exist).

        :param condition: predicate over what the harness has received
        :param max_steps: the most steps to take
        :param what: what is waited for, for the failure message (default: the condition)
        :return: steps taken (at least one chunk, at most ``max_steps``)
        :raises ConditionNotMet: when it does not hold after ``max_steps`` steps; the message
            names it and the twin's state at the end
        """
        self._check_open('step_until()')
        if max_steps < 1:
            raise ValueError(f'step_until: max_steps must be at least 1 (got {max_steps})')
        taken = 0
        while taken < max_steps:
            k = min(self.chunk, max_steps - taken)
            self.step(k)
            taken += k
            if condition():
                return taken
        raise ConditionNotMet(
            f'{what or _describe(condition)}: not met within {max_steps} steps '
            f'({max_steps * self.step_s:g} s); at the end: {self.describe_state()}')

    def wait_until(self, condition: Callable[[], bool], *, timeout: Optional[float] = None,
                   what: Optional[str] = None) -> None:
        """Serve callbacks without stepping until ``condition()`` holds (e.g. a controller in
        another process has answered).

        :param timeout: longest wait [s] (default: the harness's timeout)
        :raises ConditionNotMet: when it does not hold in time
        """
        driver = self._check_open('wait_until()')
        limit = driver.timeout if timeout is None else timeout
        from conveyor_twin.testing.ros_env import wait_for
        if not wait_for(condition, limit, driver.executor):
            raise ConditionNotMet(f'{what or _describe(condition)}: not met within {limit:g} s '
                                  f'without stepping; at the end: {self.describe_state()}'
                                  + self._controller_report())

    # -- reading -------------------------------------------------------------------------
    def _received(self, topic: str) -> List[bytes]:
        return self._check_open(f'reading {topic}').probe.received[topic]

    def messages(self, topic: str) -> List[bytes]:
        """Every message received on a stream since the start or the last reset, as CDR bytes
        (``parts``, ``density``, ``light_barriers``, ``light_barrier_edges``, ``belt_states``,
        ``actuator_states``, ``/clock``, ``command_status``)."""
        return self._received(topic)

    def digest(self, topic: str) -> str:
        """SHA-256 of every message received on ``topic`` (same seed and commands: same)."""
        self._check_open('digest()')
        return self._driver.probe.digest(topic)

    def belts(self) -> Dict[str, BeltState]:
        """Latest ``belt_states``: ``{belt: BeltState}`` (empty before the first step)."""
        data = self._received('belt_states')
        if not data:
            return {}
        msg = deserialize_message(data[-1], BeltStates)
        return {n: BeltState(c, s) for n, c, s in zip(msg.name, msg.commanded_speed, msg.speed)}

    def belt(self, name: str) -> BeltState:
        """Latest state of one belt; raise KeyError naming the known belts."""
        return _pick(self.belts(), name, 'belt')

    def belt_history(self, name: str) -> List[BeltSample]:
        """Every ``belt_states`` entry of one belt received so far, oldest first."""
        out = []
        for data in self._received('belt_states'):
            msg = deserialize_message(data, BeltStates)
            if name not in msg.name:
                raise KeyError(f'unknown belt {name!r} (known: {", ".join(msg.name)})')
            i = list(msg.name).index(name)
            out.append(BeltSample(cdr.stamp_of(data), msg.commanded_speed[i], msg.speed[i]))
        return out

    def actuators(self) -> Dict[str, ActuatorState]:
        """Latest ``actuator_states``: ``{actuator: ActuatorState}``."""
        data = self._received('actuator_states')
        if not data:
            return {}
        msg = deserialize_message(data[-1], ActuatorStates)
        return {n: ActuatorState(c, p) for n, c, p in
                zip(msg.name, msg.commanded_position, msg.position)}

    def actuator(self, name: str) -> ActuatorState:
        """Latest state of one actuator; raise KeyError naming the known actuators."""
        return _pick(self.actuators(), name, 'actuator')

    def barriers(self) -> Dict[str, BarrierState]:
        """Latest ``light_barriers``: ``{barrier: BarrierState}``."""
        data = self._received('light_barriers')
        if not data:
            return {}
        _, _, _, names, blocked, counts = cdr.decode_light_barrier_states(data[-1])
        return {n: BarrierState(bool(b), int(c)) for n, b, c in zip(names, blocked, counts)}

    def barrier(self, name: str) -> BarrierState:
        """Latest state of one light barrier; raise KeyError naming the known barriers."""
        return _pick(self.barriers(), name, 'light barrier')

    def edges(self, *, since_step: int = 0, name: Optional[str] = None) -> List[Edge]:
        """Light-barrier edges of steps after ``since_step``, in order (optionally one barrier's).

        :param since_step: only edges that happened after this step index
        :param name: only this barrier's edges
        """
        step_ns = round(self.step_s * 1e9)
        out = []
        for data in self._received('light_barrier_edges'):
            msg = deserialize_message(data, LightBarrierEdge)
            t = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            step = -(-t // step_ns)
            if step > since_step and (name is None or msg.name == name):
                out.append(Edge(msg.name, msg.blocked, msg.part_id, t, step))
        return out

    def parts(self) -> PartStates:
        """Latest ``parts``: ids, types, poses and velocities as numpy arrays (SI units)."""
        data = self._received('parts')
        if not data:
            empty = np.zeros(0)
            return PartStates(0, self.cell.settings.frame_id, 0, empty.astype(np.uint32),
                              empty.astype(np.uint16), *([empty] * 6))
        return cdr.decode_part_states(data[-1])

    def part(self, part_id: int) -> Optional[Dict[str, float]]:
        """Latest pose and velocity of one micro part (None when it is not in the micro scale
        any more: left through a sink or handed over to the macro scale)."""
        parts = self.parts()
        hits = np.flatnonzero(parts.id == part_id)
        if not len(hits):
            return None
        i = hits[0]
        return {f: float(getattr(parts, f)[i]) for f in ('x', 'y', 'yaw', 'vx', 'vy', 'wz')}

    def densities(self) -> Dict[str, DensityGrid]:
        """Latest ``density`` of every macro zone: ``{zone: grid}``, density shape (ny, nx)."""
        out: Dict[str, DensityGrid] = {}
        data = self._received('density')
        for raw in data[-max(1, density_per_step(self.cell)):]:
            grid = cdr.decode_density_grid(raw)
            out[grid.zone] = grid
        return out

    def command_log(self) -> List[CommandRecord]:
        """Every command the twin answered so far (the harness's and every controller's)."""
        out = []
        for data in self._received('command_status'):
            status = deserialize_message(data, DiagnosticStatus)
            values = {kv.key: kv.value for kv in status.values}
            out.append(CommandRecord(status.name, status.hardware_id,
                                     float(values.get('value', 'nan')), command_result(status)))
        return out

    def describe_state(self) -> str:
        """One line of the twin's state as the harness last saw it (for failure messages)."""
        if self._closed:
            return 'closed'
        belts = ', '.join(f'{n} {s.speed:.3g}/{s.commanded_speed:.3g} m/s'
                          for n, s in self.belts().items())
        actuators = ', '.join(f'{n} {s.position:.3g}/{s.commanded_position:.3g}'
                              for n, s in self.actuators().items())
        blocked = [n for n, s in self.barriers().items() if s.blocked]
        rejected = [r.result.reason for r in self.command_log() if not r.result.accepted]
        return (f'step {self.step_index} (t = {self.time:.3f} s); belts (actual/commanded): '
                f'{belts or "-"}; actuators: {actuators or "-"}; blocked barriers: '
                f'{", ".join(blocked) or "none"}; {len(self.parts().id)} micro parts; '
                f'{len(self._received("light_barrier_edges"))} edges; '
                f'{len(rejected)} rejected commands' + (f' (last: {rejected[-1]})'
                                                        if rejected else ''))

    # -- acting --------------------------------------------------------------------------
    def _command(self, msg: Union[BeltCommand, ActuatorCommand], check: bool,
                 what: str) -> CommandResult:
        result = self._check_open(what).command(msg)
        if check and not result.accepted:
            raise CommandRejectedError(result.reason)
        return result

    def set_belt(self, belt: str, speed: float, *, check: bool = True) -> CommandResult:
        """Send ``belt_command`` and wait for the twin's answer; it takes effect at the next step.

        :param belt: belt name
        :param speed: target speed along the belt [m/s]
        :param check: raise when the twin rejects it (else return the rejection)
        :raises CommandRejectedError: when rejected and ``check``; the message is the twin's
        """
        return self._command(BeltCommand(belt=belt, speed=float(speed)), check,
                             f'set_belt({belt!r})')

    def set_actuator(self, actuator: str, position: float, *,
                     check: bool = True) -> CommandResult:
        """Send ``actuator_command`` and wait for the twin's answer.

        :param actuator: actuator name
        :param position: target position [m] (linear) or [rad] (rotary)
        :param check: raise when the twin rejects it (else return the rejection)
        :raises CommandRejectedError: when rejected and ``check``
        """
        return self._command(ActuatorCommand(actuator=actuator, position=float(position)),
                             check, f'set_actuator({actuator!r})')

    def spawn(self, part_type: str, x: Sequence[float], y: Sequence[float],
              yaw: Optional[Sequence[float]] = None) -> np.ndarray:
        """Place parts now through ``spawn_parts``; return their ids.

        :param part_type: a part type of the cell
        :param x: positions [m]
        :param y: positions [m]
        :param yaw: headings [rad] (default: 0)
        :raises ServiceError: when the twin refuses (the message is the twin's)
        """
        driver = self._check_open(f'spawn({part_type!r})')
        x, y = list(np.atleast_1d(x)), list(np.atleast_1d(y))
        yaw = [0.0] * len(x) if yaw is None else list(np.atleast_1d(yaw))
        response = driver.spawn(part_type, x, y, yaw)
        if not response.success:
            raise ServiceError(f'spawn_parts refused: {response.message}')
        return np.asarray(response.id, dtype=np.uint32)

    # -- faults --------------------------------------------------------------------------
    def inject_fault(self, kind: str, target: str = '', *, duration: float = 0.0,
                     part_type: str = '', **params: float) -> int:
        """Inject a fault through ``inject_fault``; it takes effect at the next step. Return
        its id.

        :param kind: a fault kind (``docs/faults.md``), e.g. ``barrier_stuck_blocked``
        :param target: what it acts on (barrier, belt, actuator, source, stream or command
            topic name; a part id); empty for ``parts_vanish``
        :param duration: clear it after this long [s]; 0: until cleared
        :param part_type: the part type ``source_wrong_type`` delivers
        :param params: the kind's parameters [SI], e.g. ``frequency=20.0``
        :raises FaultRejectedError: when the twin refuses (the message is the twin's)
        """
        from conveyor_twin_msgs.srv import InjectFault
        driver = self._check_open(f'inject_fault({kind!r})')
        response = driver.inject_fault(InjectFault.Request(
            kind=kind, target=str(target), param_names=list(params),
            param_values=[float(v) for v in params.values()], duration=float(duration),
            part_type=part_type))
        if not response.success:
            raise FaultRejectedError(response.message)
        return int(response.id)

    def clear_fault(self, fault_id: int) -> None:
        """Clear a fault through ``clear_fault``; it takes effect at the next step.

        :raises FaultRejectedError: when no fault of that id is active
        """
        response = self._check_open(f'clear_fault({fault_id})').clear_fault(fault_id)
        if not response.success:
            raise FaultRejectedError(response.message)

    def active_faults(self) -> Dict[int, FaultEntry]:
        """Return the active faults by id, as the ``faults`` stream stated them after the last
        step (a fault injected since takes effect at the next step)."""
        state = self._check_open('active_faults()').fault_state()
        return {} if state is None else {f.id: f for f in state.active}

    def reset(self, *, seed: Optional[int] = None, cell_file: Union[None, str, Path] = None
              ) -> None:
        """Restart the twin at step 0 through ``reset``; forget every message received.

        :param seed: new seed (default: the current one)
        :param cell_file: another cell file with the same belts, actuators and barriers
        :raises ServiceError: when the twin refuses (the message is the twin's)
        """
        driver = self._check_open('reset()')
        driver.settle_edges()
        self.seed = self.seed if seed is None else seed
        response = driver.reset(self.seed, os.fspath(cell_file) if cell_file else '')
        if not response.success:
            raise ServiceError(f'reset refused: {response.message}')
        if cell_file:
            self.cell = load_cell(cell_file)
        for messages in driver.probe.received.values():
            messages.clear()
        self.step_index = self.time_ns = 0

    # -- controllers ---------------------------------------------------------------------
    def add_node(self, node: Node) -> Node:
        """Attach a controller node of this process: it is spun whenever the harness waits.

        Create it on :attr:`context` (``MyController(context=twin.context)``); the twin
        destroys it at :meth:`close`.

        :return: the node
        """
        self._check_open('add_node()').executor.add_node(node)
        self._nodes.append(node)
        return node

    def start_controller(self, args: Sequence[str], *,
                         env: Optional[Mapping[str, str]] = None) -> subprocess.Popen:
        """Start a controller as its own process in the twin's domain (loopback discovery);
        it is stopped (SIGINT, SIGTERM, SIGKILL) at :meth:`close`.

        :param args: command line, e.g. ``[sys.executable, 'my_controller.py']``
        :param env: more environment variables
        :return: the process; its output is in :meth:`controller_output`
        """
        self._check_open('start_controller()')
        index = len(self._controllers)
        with open(self._log_dir / f'controller_{index}.log', 'w') as log:
            process = self._processes.start(list(args), env=env, stdout=log,
                                            stderr=subprocess.STDOUT)
        self._controllers.append(process)
        return process

    def controller_output(self, index: int = 0) -> str:
        """Return what a started controller has printed so far (stdout and stderr)."""
        path = self._log_dir / f'controller_{index}.log'
        return path.read_text(errors='replace') if path.exists() else ''

    def _controller_report(self) -> str:
        lines = []
        for i, process in enumerate(self._controllers):
            code = process.poll()
            state = 'running' if code is None else f'exited with {code}'
            lines.append(f'\n--- controller {i} ({state}):\n{self.controller_output(i)[-2000:]}')
        return ''.join(lines)

    def wait_for_node(self, name: str, *, subscribes: Sequence[str] = (),
                      publishes: Sequence[str] = (), timeout: Optional[float] = None) -> None:
        """Wait until a node (e.g. a started controller) is discovered with the subscriptions
        and publishers given (topic names relative to the twin, e.g. ``'light_barriers'``).

        :raises ConditionNotMet: when it is not, or a started controller exits meanwhile; the
            message carries the controllers' output
        """
        driver = self._check_open('wait_for_node()')
        probe = driver.probe

        def endpoints(infos: Any) -> bool:
            return any(i.node_name == name for i in infos)

        def ready() -> bool:
            if any(p.poll() is not None for p in self._controllers):
                return True
            return (all(endpoints(probe.get_subscriptions_info_by_topic(_abs(t)))
                        for t in subscribes)
                    and all(endpoints(probe.get_publishers_info_by_topic(_abs(t)))
                            for t in publishes)
                    and name in probe.get_node_names())

        self.wait_until(ready, timeout=timeout, what=f'node {name!r} discovered')
        dead = [p for p in self._controllers if p.poll() is not None]
        if dead:
            raise ConditionNotMet(f'node {name!r}: a controller process exited before it was '
                                  f'discovered{self._controller_report()}')


def _abs(topic: str) -> str:
    return topic if topic.startswith('/') else '/' + topic


def _pick(states: Dict[str, Any], name: str, kind: str) -> Any:
    try:
        return states[name]
    except KeyError:
        known = ', '.join(states) or 'none received yet: step first'
        raise KeyError(f'unknown {kind} {name!r} (known: {known})') from None


def _describe(condition: Callable[[], bool]) -> str:
    doc = (getattr(condition, '__doc__', None) or '').strip()
    name = getattr(condition, '__name__', repr(condition))
    return doc.splitlines()[0] if doc and name != '<lambda>' else f'condition {name}'
