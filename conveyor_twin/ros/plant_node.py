"""A plant of cells over ROS 2: every cell in one process, and where the other parts live.

:class:`ComposedPlant` runs every cell in this process with
:class:`~conveyor_twin.plant.runner.PlantRunner` (batches handed over in memory) and publishes
every cell's ``progress`` as the cells in processes of their own do. A failure of its stepping
or executor thread is reported once to :attr:`ComposedPlant.health` and ends the run.

The other modules of the plant's ROS layer: :mod:`conveyor_twin.ros.plant_cell_node` (one cell
per process, coupled over the links' topics), :mod:`conveyor_twin.ros.plant_monitor` (the
plant-wide ledger and diagnostics) and :mod:`conveyor_twin.ros.plant_messages` (the messages,
converted from and to the link ends' batches). Their public names are re-exported here.
"""

import threading
import time
from typing import List, Optional

from rclpy.context import Context
from rclpy.node import Node

from conveyor_twin import contract
from conveyor_twin.coord.clock import step_ns
from conveyor_twin.coord.timing import DeadlinePacer, StepStats, TimeMode
from conveyor_twin.health import Health
from conveyor_twin.plant.ledger import ledger_of
from conveyor_twin.plant.model import Plant
from conveyor_twin.plant.runner import PlantRunner
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.plant_cell_node import (PEER_GONE_AFTER, PROGRESS_PERIOD, WAIT_PERIOD,
                                               PlantCellNode, record_cell, sync_period)
from conveyor_twin.ros.plant_messages import (CellProgress, PartTransfer, TransferAccepted,
                                              acceptances_msg, acceptances_of, departures_msg,
                                              departures_of, progress_msg, report_of)
from conveyor_twin.ros.plant_monitor import PlantMonitor
from conveyor_twin.ros.qos import to_rclpy

__all__ = ['CellProgress', 'ComposedPlant', 'PEER_GONE_AFTER', 'PROGRESS_PERIOD', 'PartTransfer',
           'PlantCellNode', 'PlantMonitor', 'TransferAccepted', 'WAIT_PERIOD', 'acceptances_msg',
           'acceptances_of', 'departures_msg', 'departures_of', 'ledger_of', 'progress_msg',
           'record_cell', 'report_of', 'sync_period']


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
        self.stats = StepStats()
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
        self._threads: List[threading.Thread] = []
        self.wall_start = self.wall_end = 0.0

    def _refuse_step(self, n: int = 1) -> None:
        self.node.get_logger().warning('step service ignored: the plant steps this cell')

    def _publish(self, done: bool) -> None:
        rtf = self.real_time_factor()
        for core in self.runner.cells:
            self._progress_pub.publish(progress_msg(core, end_step=self.end_step, done=done,
                                                    stats=self.stats, rtf=rtf,
                                                    with_hash=done))

    def real_time_factor(self) -> float:
        """Simulated over wall time of the stepping so far."""
        end = self.wall_end or time.monotonic()
        wall = end - self.wall_start if self.wall_start else 0.0
        return self.runner.step_index * self.plant.step / wall if wall > 0 else 0.0

    def _loop(self) -> None:
        runner = self.runner
        end = self.end_step or (1 << 62)
        pacer = DeadlinePacer(step_ns(self.plant.step))
        self.wall_start = time.monotonic()
        pacer.restart()
        try:
            while not self._stop.is_set() and runner.step_index < end:
                t0 = time.perf_counter()
                if self.mode is TimeMode.FAST:
                    target = min(end, runner.step_index + self.period)
                    runner.run_to(target)
                    n = self.period
                else:
                    runner.step(1)
                    n = 1
                self.stats.add((time.perf_counter() - t0) / n)  # mean per plant step
                if time.monotonic() - self._progress_at >= PROGRESS_PERIOD:
                    self._progress_at = time.monotonic()
                    self._publish(False)
                if self.mode is TimeMode.REALTIME:
                    pacer.wait_next()
            self.wall_end = time.monotonic()
            self._publish(runner.step_index >= end)
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
        stepper = threading.Thread(target=self._loop, name='plant_steps', daemon=True)
        stepper.start()
        self._threads += [spin, stepper]

    def stop(self) -> None:
        """Stop stepping and serving; destroy the nodes."""
        self._stop.set()
        for t in self._threads:
            t.join(5.0)
        for ct in self.composed.values():
            ct.stop()
        for recording in self.recordings:
            recording.close()
        self.executor.shutdown(timeout_sec=5.0)
        self.node.destroy_node()
