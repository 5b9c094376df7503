"""The life cycle of a :class:`~conveyor_twin.testing.LockstepTwin`: start, failure, close.

:class:`TwinLifecycle` is the base every part of the harness builds on: it holds the started
twin (its ROS domain lease, rclpy context, layout, :class:`~conveyor_twin.testing.driver.Driver`
and :class:`~conveyor_twin.testing.supervision.Supervisor`), gives the other parts the driver
for a call (:meth:`TwinLifecycle._check_open`, :meth:`TwinLifecycle._acting`), marks the twin
failed on a timeout, a background failure or an unmet condition (:meth:`TwinLifecycle._failing`),
and closes it without a trace unless it failed.
"""

from contextlib import contextmanager
from pathlib import Path
import shutil
import tempfile
from typing import Any, Iterator, List, Optional

import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from conveyor_twin.cell.model import Cell
from conveyor_twin.health import BackgroundFailure
from conveyor_twin.coord.layout import Layout
from conveyor_twin.testing._layout import density_per_step, RunningLayout, start_layout
from conveyor_twin.testing.driver import Driver
from conveyor_twin.testing.errors import ConditionNotMet, TwinClosedError, TwinTimeoutError
from conveyor_twin.testing.kernels import ready_kernels
from conveyor_twin.testing.processes import RosProcesses
from conveyor_twin.testing.ros_env import DomainLease, lease_domain_id, loopback_environment
from conveyor_twin.testing.supervision import keep_dir_note, Supervisor

#: The failures that keep the twin's logs and name where they are.
FAILURES = (TwinTimeoutError, BackgroundFailure, ConditionNotMet)


class TwinLifecycle:
    """Start, watch and close a lockstep twin (the base of
    :class:`~conveyor_twin.testing.LockstepTwin`)."""

    cell: Cell
    scenario: Any
    seed: int
    layout: Layout
    chunk: int
    step_s: float
    step_index: int
    time_ns: int
    domain_id: int
    context: Optional[Context]

    def _start(self, cell_file: Optional[str], *, timeout: float, foxglove: str,
               plc: Any = None) -> None:
        """Have the kernels ready, lease a domain, start the twin of :attr:`cell` and connect
        the driver to it; on any failure, close what was started and raise.

        The kernels are compiled (or loaded) first with their own budget
        (:func:`~conveyor_twin.testing.kernels.ready_kernels`), so ``timeout`` never covers a
        compile."""
        self._closed = False
        self._failed = False
        self._raised = 0  # background failures already raised to the test
        self._nodes: List[Node] = []
        self._log_dir = Path(tempfile.mkdtemp(prefix='conveyor_twin_test_'))
        self._lease: Optional[DomainLease] = lease_domain_id()
        self.domain_id = self._lease.domain_id
        self._processes = RosProcesses(domain_id=self.domain_id)
        self._running: Optional[RunningLayout] = None
        self._driver: Optional[Driver] = None
        self._supervisor: Optional[Supervisor] = None
        self.context = None
        try:
            with self._failing():
                ready_kernels(self.cell, self.seed, timeout=timeout)
            context = Context()
            with loopback_environment():
                rclpy.init(context=context, domain_id=self.domain_id,
                           signal_handler_options=SignalHandlerOptions.NO)
            self.context = context
            self._running = start_layout(self.cell, cell_file, seed=self.seed,
                                         layout=self.layout, context=self.context,
                                         domain_id=self.domain_id, log_dir=self._log_dir,
                                         foxglove=foxglove, scenario=self.scenario, plc=plc)
            self._supervisor = Supervisor(self._running, self._log_dir, self._processes)
            self._driver = Driver(self.context, density_per_step=density_per_step(self.cell),
                                  name='conveyor_twin_test', timeout=timeout)
            self._driver.watch = self._supervisor.check
            self._driver.after_chunk = self._after_chunk
            with self._failing():
                if not self._driver.wait_connected():
                    raise TwinTimeoutError(f'the {self.layout} twin was not discovered within '
                                           f'{timeout:g} s\n{self._running.logs()}')
        except BaseException:
            self._failed = True
            self.close()
            raise

    def _after_chunk(self, stamp_ns: int) -> None:
        self._supervisor.wait_paced(self._driver, stamp_ns)

    # -- life cycle ----------------------------------------------------------------------
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
        except FAILURES as exc:
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
    def plc(self) -> Any:
        """The PLC servers of a composed twin started with ``opcua=``/``modbus=``
        (:class:`~conveyor_twin.plc.attach.PlcServers`: ``opcua_url``, ``modbus_port``), else
        None."""
        composed = self.composed
        return composed.plc if composed is not None else None

    @property
    def composed(self) -> Any:
        """The in-process twin of the composed layout (None when split), for white-box tests of
        the twin itself; not part of the stable API."""
        return self._running.composed if self._running is not None else None
