"""A lockstep twin for tests: started in-process in a ROS domain of its own, driven over ROS.

:class:`LockstepTwin` starts the twin of a cell (composed in this process, or split over three
processes) in ``lockstep`` mode, in a private rclpy context on a domain id no other test holds
(loopback discovery only), and drives it the way a controller would: through the ``step``,
``spawn_parts`` and ``reset`` services, the command topics and the streams. Nothing it does
reads the twin's internals, so what a test sees is what a controller sees.
"""

from contextlib import contextmanager
import os
from pathlib import Path
import shutil
import subprocess
import tempfile
from typing import (Any, Callable, Dict, Iterator, List, Mapping, Optional, Sequence, Union)

from conveyor_twin_msgs.msg import ActuatorCommand, BeltCommand
import numpy as np
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell
from conveyor_twin.health import BackgroundFailure
from conveyor_twin.testing import checks
from conveyor_twin.testing._layout import density_per_step, Layout, LAYOUTS, start_layout
from conveyor_twin.testing.driver import CommandResult, Driver, TIMEOUT
from conveyor_twin.testing.errors import (CommandRejectedError, ConditionNotMet,
                                          FaultRejectedError, ServiceError,
                                          TwinClosedError, TwinTimeoutError)
from conveyor_twin.testing.processes import RosProcesses
from conveyor_twin.testing.reading import DensityGrid, PartStates, StreamReader
from conveyor_twin.testing.ros_env import (DomainLease, lease_domain_id,
                                           loopback_environment, wait_for)
from conveyor_twin.testing.states import (ActuatorState, BarrierState, BeltSample, BeltState,
                                          CommandRecord, Edge)
from conveyor_twin.testing.supervision import keep_dir_note, Supervisor
from conveyor_twin.wire.fault_state import FaultEntry

DEFAULT_CHUNK = 10      # steps per ``step`` service call: a controller reacts within this many
DEFAULT_SEED = 0
#: The failures that keep the twin's logs and name where they are.
_FAILURES = (TwinTimeoutError, BackgroundFailure, ConditionNotMet)

__all__ = ['ActuatorState', 'BarrierState', 'BeltSample', 'BeltState', 'CommandRecord',
           'DEFAULT_CHUNK', 'DensityGrid', 'Edge', 'LockstepTwin', 'PartStates']


class LockstepTwin(StreamReader):
    """A twin in lockstep, started for a test; a context manager.

    :param cell: a cell file, a :class:`~conveyor_twin.cell.model.Cell`, or None for the
        embedded default cell
    :param seed: random seed of the run (an integer in [0, 2**64 - 1])
    :param layout: ``composed`` (one process: this one) or ``split`` (three processes; needs a
        cell file or the default cell)
    :param chunk: steps per ``step`` service call; between calls the harness waits for every
        stream and for the twin's answer to every command, so an attached controller reacts
        within ``chunk`` steps
    :param timeout: longest wait for any one answer of the twin or a controller [s] (> 0)
    :param foxglove: ``[HOST:]PORT`` to serve a live Foxglove view of the test's twin at (watch
        a test step by step); None: no view. Composed: port 0 picks a free one, see
        :attr:`foxglove`; split: the coordinator process serves it, give a port.
    :param scenario: a fault scenario file to arm (``docs/faults.md``); checked before the
        twin starts
    :raises ValueError: on an unknown layout, a seed, chunk or timeout out of range (the
        message names it, the value and the range), an invalid ``foxglove`` address, or port 0
        with the split layout
    :raises conveyor_twin.faults.scenario.ScenarioError: on an invalid scenario file
    :raises conveyor_twin.viz.foxglove_view.FoxgloveError: if the view cannot listen there
    :raises conveyor_twin.cell.CellError: on an invalid cell file

    The twin leaves no trace: the process's environment is not changed (the domain id and
    loopback discovery go to its own rclpy context and its child processes), and its folder
    of logs (split processes, controller processes) is removed at :meth:`close` unless the
    twin failed; then the error names the folder.
    """

    def __init__(self, cell: Union[None, str, Path, Cell] = None, *, seed: int = DEFAULT_SEED,
                 layout: Layout = 'composed', chunk: int = DEFAULT_CHUNK,
                 timeout: float = TIMEOUT, foxglove: Optional[str] = None,
                 scenario: Union[None, str, Path] = None) -> None:
        seed = checks.integer('seed', seed, 0, checks.UINT64_MAX)
        chunk = checks.integer('chunk', chunk, 1, checks.UINT32_MAX)
        timeout = checks.seconds('timeout', timeout, open_low=True)
        if layout not in LAYOUTS:
            raise ValueError(f'layout {layout!r} is not one of {", ".join(LAYOUTS)}')
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
        self._failed = False
        self._raised = 0  # background failures already raised to the test
        self._nodes: List[Node] = []
        self._log_dir = Path(tempfile.mkdtemp(prefix='conveyor_twin_test_'))
        self._lease: Optional[DomainLease] = lease_domain_id()
        self.domain_id = self._lease.domain_id
        self._processes = RosProcesses(domain_id=self.domain_id)
        self._running = None
        self._driver: Optional[Driver] = None
        self._supervisor: Optional[Supervisor] = None
        self.context: Optional[Context] = None
        try:
            context = Context()
            with loopback_environment():
                rclpy.init(context=context, domain_id=self.domain_id,
                           signal_handler_options=SignalHandlerOptions.NO)
            self.context = context
            self._running = start_layout(self.cell, cell_file, seed=seed, layout=layout,
                                         context=self.context, domain_id=self.domain_id,
                                         log_dir=self._log_dir, foxglove=foxglove or '',
                                         scenario=self.scenario)
            self._supervisor = Supervisor(self._running, self._log_dir, self._processes)
            self._driver = Driver(self.context, density_per_step=density_per_step(self.cell),
                                  name='conveyor_twin_test', timeout=timeout)
            self._driver.watch = self._supervisor.check
            self._driver.after_chunk = self._after_chunk
            with self._failing():
                if not self._driver.wait_connected():
                    raise TwinTimeoutError(f'the {layout} twin was not discovered within '
                                           f'{timeout:g} s\n{self._running.logs()}')
        except BaseException:
            self._failed = True
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

    @property
    def log_dir(self) -> Path:
        """The twin's folder of logs (split processes, controllers); removed at :meth:`close`
        unless the twin failed."""
        return self._log_dir

    def _check_open(self, what: str) -> Driver:
        if self._closed or self._driver is None:
            raise TwinClosedError(f'{what}: the twin is closed (used after close() or outside '
                                  'its with block)')
        return self._driver

    def _acting(self, what: str) -> Driver:
        """The driver, for a call that drives the twin: raise when the twin is closed or
        a background thread or process failed."""
        driver = self._check_open(what)
        with self._failing():
            self._supervisor.check()
        return driver

    @contextmanager
    def _failing(self) -> Iterator[None]:
        """Mark the twin failed on a timeout, a background failure or an unmet condition,
        and name the folder of its logs (kept) in the error."""
        try:
            yield
        except _FAILURES as exc:
            self._failed = True
            if isinstance(exc, BackgroundFailure):
                self._raised = len(exc.failures)
            note = keep_dir_note(self._log_dir)
            if any(self._log_dir.iterdir()) and note not in str(exc):
                exc.args = (f'{exc}{note}',) + exc.args[1:]
            raise

    def unreported_failures(self) -> Optional[BackgroundFailure]:
        """Return the background failures the test was not told of yet (None if none): what
        failed after the last call that drove the twin (the pytest fixtures raise it)."""
        if self._supervisor is None or self._closed:
            return None
        try:
            self._supervisor.check()
        except BackgroundFailure as exc:
            if len(exc.failures) > self._raised:
                self._failed = True
                return exc
        return None

    def close(self) -> None:
        """Stop controllers, attached nodes and the twin; release the domain; remove the folder
        of logs unless the twin failed. Idempotent."""
        if self._closed:
            return
        if self._supervisor is not None and self._supervisor.failed():
            self._failed = True
        self._closed = True
        try:
            if self._supervisor is not None:
                self._supervisor.stop()
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
            if not (self._failed and self._log_dir.exists() and any(self._log_dir.iterdir())):
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
                f'{what or _describe(condition)}: not met within {max_steps} steps '
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
                raise ConditionNotMet(f'{what or _describe(condition)}: not met within '
                                      f'{limit:g} s without stepping; at the end: '
                                      f'{self.describe_state()}'
                                      + self._supervisor.report())

    def _after_chunk(self, stamp_ns: int) -> None:
        self._supervisor.wait_paced(self._driver, stamp_ns)

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

    # -- acting --------------------------------------------------------------------------
    def _command(self, msg: Union[BeltCommand, ActuatorCommand], check: bool,
                 what: str) -> CommandResult:
        driver = self._acting(what)
        with self._failing():
            result = driver.command(msg)
        if check and not result.accepted:
            raise CommandRejectedError(result.reason)
        return result

    def set_belt(self, belt: str, speed: float, *, check: bool = True) -> CommandResult:
        """Send ``belt_command`` and wait for the twin's answer; it takes effect at the next step.

        The command carries ``sender`` ``conveyor_twin_test`` and the next ``sequence`` number;
        the answer is the ``command_status`` that echoes both.

        :param belt: belt name
        :param speed: target speed along the belt [m/s] (any real number: the twin judges it)
        :param check: raise when the twin rejects it (else return the rejection)
        :raises ValueError: when ``speed`` is not a real number
        :raises CommandRejectedError: when rejected and ``check``; the message is the twin's
        """
        return self._command(BeltCommand(belt=_name('belt', belt),
                                         speed=checks.number('speed', speed)),
                             check, f'set_belt({belt!r})')

    def set_actuator(self, actuator: str, position: float, *,
                     check: bool = True) -> CommandResult:
        """Send ``actuator_command`` and wait for the twin's answer.

        :param actuator: actuator name
        :param position: target position [m] (linear) or [rad] (rotary); any real number
        :param check: raise when the twin rejects it (else return the rejection)
        :raises ValueError: when ``position`` is not a real number
        :raises CommandRejectedError: when rejected and ``check``
        """
        return self._command(ActuatorCommand(actuator=_name('actuator', actuator),
                                             position=checks.number('position', position)),
                             check, f'set_actuator({actuator!r})')

    def spawn(self, part_type: str, x: Sequence[float], y: Sequence[float],
              yaw: Optional[Sequence[float]] = None) -> np.ndarray:
        """Place parts now through ``spawn_parts``; return their ids.

        :param part_type: a part type of the cell
        :param x: positions [m]
        :param y: positions [m]
        :param yaw: headings [rad] (default: 0)
        :raises ValueError: when a pose is not a real number
        :raises ServiceError: when the twin refuses (the message is the twin's: an unknown
            type, a pose off the belts or outside the walls, an overlap)
        """
        x, y = checks.numbers_of('x', x), checks.numbers_of('y', y)
        yaw = [0.0] * len(x) if yaw is None else checks.numbers_of('yaw', yaw)
        driver = self._acting(f'spawn({part_type!r})')
        with self._failing():
            response = driver.spawn(_name('part_type', part_type), x, y, yaw)
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
        :raises ValueError: when ``duration`` or a parameter is not a real number
        :raises FaultRejectedError: when the twin refuses (the message is the twin's)
        """
        from conveyor_twin_msgs.srv import InjectFault
        duration = checks.number('duration', duration)
        values = [checks.number(f'parameter {k}', v) for k, v in params.items()]
        driver = self._acting(f'inject_fault({kind!r})')
        with self._failing():
            response = driver.inject_fault(InjectFault.Request(
                kind=_name('kind', kind), target=str(target), param_names=list(params),
                param_values=values, duration=duration, part_type=_name('part_type', part_type)))
        if not response.success:
            raise FaultRejectedError(response.message)
        return int(response.id)

    def clear_fault(self, fault_id: int) -> None:
        """Clear a fault through ``clear_fault``; it takes effect at the next step.

        :param fault_id: the id :meth:`inject_fault` returned (an integer in [0, 2**32 - 1])
        :raises FaultRejectedError: when no fault of that id is active
        """
        fault_id = checks.integer('fault_id', fault_id, 0, checks.UINT32_MAX)
        driver = self._acting(f'clear_fault({fault_id})')
        with self._failing():
            response = driver.clear_fault(fault_id)
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

        :param seed: new seed (default: the current one; an integer in [0, 2**64 - 1])
        :param cell_file: another cell file with the same belts, actuators and barriers
        :raises ServiceError: when the twin refuses (the message is the twin's)
        """
        if seed is not None:
            seed = checks.integer('seed', seed, 0, checks.UINT64_MAX)
        driver = self._acting('reset()')
        with self._failing():
            driver.settle_edges()
            new_seed = self.seed if seed is None else seed
            response = driver.reset(new_seed, os.fspath(cell_file) if cell_file else '')
        if not response.success:
            raise ServiceError(f'reset refused: {response.message}')
        self.seed = new_seed
        if cell_file:
            self.cell = load_cell(cell_file)
        driver.forget()
        self._supervisor.forget_acks()
        self.step_index = self.time_ns = 0

    # -- controllers ---------------------------------------------------------------------
    def add_node(self, node: Node) -> Node:
        """Attach a controller node of this process: it is spun whenever the harness waits.

        Create it on :attr:`context` (``MyController(context=twin.context)``); the twin
        destroys it at :meth:`close`. An exception its callbacks raise ends the harness's
        wait with that exception.

        :return: the node
        """
        self._acting('add_node()').executor.add_node(node)
        self._nodes.append(node)
        return node

    def start_controller(self, args: Sequence[str], *,
                         env: Optional[Mapping[str, str]] = None,
                         pace: Optional[str] = None) -> subprocess.Popen:
        """Start a controller as its own process in the twin's domain (loopback discovery);
        it is stopped (SIGINT, SIGTERM, SIGKILL) at :meth:`close`. If it ends with a non-zero
        exit code (or by a signal) before, the next call that drives the twin raises
        :class:`~conveyor_twin.health.BackgroundFailure` naming it, its exit code and the end
        of its output.

        :param args: command line, e.g. ``[sys.executable, 'my_controller.py']``
        :param env: more environment variables
        :param pace: the name of the controller's node, if it acknowledges what it read on
            ``lockstep_ack`` (:mod:`conveyor_twin.testing.pacing`): after every chunk the
            harness then waits until it acknowledged the chunk's last stamp and the twin
            answered the commands it sent before; None: not paced
        :return: the process; its output is in :meth:`controller_output`
        """
        if pace is not None and (not isinstance(pace, str) or not pace):
            raise ValueError(f'pace = {pace!r} is not allowed: it must be the name of the '
                             "controller's node or None")
        driver = self._acting('start_controller()')
        return self._supervisor.start(args, env, pace or '', driver).process

    def controller_output(self, index: int = 0) -> str:
        """Return what a started controller has printed so far (stdout and stderr).

        :param index: the controller's number in the order started (from 0)
        """
        self._check_open('controller_output()')
        count = len(self._supervisor.controllers)
        if count:
            checks.integer('controller_output(index): index', index, 0, count - 1)
        return self._supervisor.output(index)

    def wait_for_node(self, name: str, *, subscribes: Sequence[str] = (),
                      publishes: Sequence[str] = (), timeout: Optional[float] = None) -> None:
        """Wait until a node (e.g. a started controller) is discovered with the subscriptions
        and publishers given (topic names relative to the twin, e.g. ``'light_barriers'``).

        :param timeout: longest wait [s] (> 0; default: the harness's timeout)
        :raises ConditionNotMet: when it is not, or a started controller exits meanwhile; the
            message carries the controllers' output
        """
        timeout = checks.seconds('wait_for_node: timeout', timeout, open_low=True,
                                 optional=True)
        driver = self._check_open('wait_for_node()')
        probe = driver.probe
        controllers = self._supervisor.controllers

        def endpoints(infos: Any) -> bool:
            return any(i.node_name == name for i in infos)

        def ready() -> bool:
            if any(c.process.poll() is not None for c in controllers):
                return True
            return (all(endpoints(probe.get_subscriptions_info_by_topic(_abs(t)))
                        for t in subscribes)
                    and all(endpoints(probe.get_publishers_info_by_topic(_abs(t)))
                            for t in publishes)
                    and name in probe.get_node_names())

        limit = driver.timeout if timeout is None else timeout
        with self._failing():
            if not wait_for(ready, limit, driver.executor):
                raise ConditionNotMet(f'node {name!r} discovered: not met within {limit:g} s'
                                      + self._supervisor.report())
            if any(c.process.poll() is not None for c in controllers):
                raise ConditionNotMet(f'node {name!r}: a controller process exited before it '
                                      f'was discovered{self._supervisor.report()}')


def _abs(topic: str) -> str:
    return topic if topic.startswith('/') else '/' + topic


def _name(what: str, value: Any) -> str:
    if not isinstance(value, str):
        raise ValueError(f'{what} = {value!r} is not allowed: it must be a string')
    return value


def _describe(condition: Callable[[], bool]) -> str:
    doc = (getattr(condition, '__doc__', None) or '').strip()
    name = getattr(condition, '__name__', repr(condition))
    return doc.splitlines()[0] if doc and name != '<lambda>' else f'condition {name}'
