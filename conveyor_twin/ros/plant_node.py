"""A plant of cells over ROS 2: every cell in one process, and where the other parts live.

:class:`ComposedPlant` runs every cell in this process with
:class:`~conveyor_twin.plant.runner.PlantRunner` (batches handed over in memory), stepped by a
:class:`~conveyor_twin.coord.runner.Runner` (:class:`~conveyor_twin.plant.stepping.PlantStepping`),
and publishes every cell's ``progress`` as the cells in processes of their own do. A failure
of its stepping or executor thread is reported once to :attr:`ComposedPlant.health` and ends
the run.

The other modules of the plant's ROS layer: :mod:`conveyor_twin.ros.plant_cell_node` (one cell
per process, coupled over the links' topics), :mod:`conveyor_twin.ros.plant_monitor` (the
plant-wide ledger and diagnostics) and :mod:`conveyor_twin.ros.plant_messages` (the messages,
converted from and to the link ends' batches).
"""

import threading
import time
from typing import List, Optional

from rclpy.context import Context
from rclpy.node import Node

from conveyor_twin import contract
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import StepStats, TimeMode
from conveyor_twin.health import Health
from conveyor_twin.plant.model import Plant
from conveyor_twin.plant.runner import PlantRunner
from conveyor_twin.plant.stepping import PlantStepping, sync_period
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.plant_cell_node import PROGRESS_PERIOD, record_cell
from conveyor_twin.ros.plant_messages import CellProgress, progress_msg
from conveyor_twin.ros.qos import to_rclpy


class ComposedPlant:
    """Every cell of a plant in this process, stepped by one thread, batches in memory.

    :param plant: the validated plant. :param context: an initialised rclpy Context.
    :param mode: realtime (the plant paced by the wall clock), fast, or lockstep (the plant
        steps as one).
    :param end_step: the step to run to (0: until :meth:`stop`).
    :param streams: serve every cell's own interface under its namespace.
    :param record: folder to record each cell's streams to (``<cell>.mcap``; with streams).
    """

    def __init__(self, plant: Plant, *, context: Context, mode: TimeMode, end_step: int = 0,
                 streams: bool = True, record: str = '') -> None:
        self.plant = plant
        self.mode = TimeMode(mode)
        self.end_step = int(end_step)
        self.composed = {}
        twins = {}
        if streams:
            from conveyor_twin.ros.compose import ComposedTwin
            for c in plant.cells:
                ct = ComposedTwin(c.cell, seed=c.seed, mode=TimeMode.LOCKSTEP, context=context,
                                  namespace='/' + c.namespace)
                ct.runner.step = self._refuse_step
                self.composed[c.name] = ct
                twins[c.name] = ct.assembled
        self.recordings = [record_cell(self.composed[c.name], plant, c.name, record, self.mode)
                           for c in plant.cells if record and c.name in self.composed]
        self.runner = PlantRunner(plant, twins=twins)
        self.period = sync_period(plant, self.mode)
        self.node = Node('plant_composed', namespace='/' + plant.namespace, context=context)
        self._progress_pub = self.node.create_publisher(
            CellProgress, contract.CELL_PROGRESS.name, to_rclpy(contract.CELL_PROGRESS.qos))
        self._progress_at = 0.0
        self.executor = make_executor(context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self.done = threading.Event()
        self.error: Optional[BaseException] = None
        #: Where the plant's stepping and executor threads report a failure (each cell's
        #: own threads report to its twin's health: :meth:`failures` has them all).
        self.health = Health()
        fast = self.mode is TimeMode.FAST
        #: Steps the plant: in fast mode a sync period at a time, each cell as far ahead as
        #: the rule allows; else every cell one step per step (realtime: paced, as before,
        #: without the tuning of a cell twin's stepping thread).
        self.stepper = Runner(PlantStepping(self.runner, self.health, ahead=fast), self.mode,
                              max_steps=self.end_step or None,
                              chunk=self.period if fast else 1, on_error=self._failed,
                              name='plant stepping thread')
        self.stepper.tuned = self.stepper.warm_up = False
        self.stepper.listeners.append(self._report)
        self._threads: List[threading.Thread] = []

    def _refuse_step(self, n: int = 1) -> None:
        self.node.get_logger().warning('step service ignored: the plant steps this cell')

    def _publish(self, done: bool) -> None:
        rtf = self.real_time_factor()
        for core in self.runner.cells:
            self._progress_pub.publish(progress_msg(core, end_step=self.end_step, done=done,
                                                    stats=self.stats, rtf=rtf,
                                                    with_hash=done))

    @property
    def stats(self) -> StepStats:
        """Durations of the plant's steps [s] (in fast mode each sync period's mean)."""
        return self.stepper.stats

    def real_time_factor(self) -> float:
        """Simulated over wall time of the stepping so far."""
        return self.stepper.real_time_factor()

    def _report(self) -> None:
        """After a step: publish the progress if :data:`PROGRESS_PERIOD` has passed."""
        if time.monotonic() - self._progress_at >= PROGRESS_PERIOD:
            self._progress_at = time.monotonic()
            self._publish(False)

    def _failed(self, exc: BaseException) -> None:
        self.error = exc

    def _run(self) -> None:
        """The stepping thread: step to the end, then publish the last progress."""
        try:
            self.stepper.run()
            if self.error is None:
                self._publish(bool(self.end_step)
                              and self.runner.step_index >= self.end_step)
        except BaseException as exc:
            self.error = exc
            self.health.report('plant stepping thread', exc)
        finally:
            self.done.set()

    def failures(self) -> List[str]:
        """Every failure so far, of the plant's threads and of each cell twin's."""
        found = [f.describe() for f in self.health.failures]
        for name, ct in self.composed.items():
            found += [f'cell {name!r}: {f.describe()}' for f in ct.health.failures]
        return found

    def all_done(self) -> bool:
        """True once the plant completed the end step."""
        return self.done.is_set()

    def start(self) -> None:
        """Start serving callbacks and the stepping thread."""
        for ct in self.composed.values():
            ct.start()
        spin = self.health.thread('plant executor', spin_until, self.executor, self._stop)
        spin.start()
        stepper = threading.Thread(target=self._run, name='plant_steps', daemon=True)
        stepper.start()
        self._threads += [spin, stepper]

    def stop(self) -> None:
        """Stop stepping and serving; destroy the nodes."""
        self._stop.set()
        self.stepper.request_stop()
        for t in self._threads:
            t.join(5.0)
        for ct in self.composed.values():
            ct.stop()
        for recording in self.recordings:
            recording.close()
        self.executor.shutdown(timeout_sec=5.0)
        self.node.destroy_node()
