"""One cell of a plant over ROS 2: its node, the links' batches on topics.

:class:`PlantCellNode` runs one cell (:class:`~conveyor_twin.plant.cell.PlantCellCore`) in this
process: with ``streams`` the cell's whole interface (a lockstep
:class:`~conveyor_twin.ros.compose.ComposedTwin` under the cell's namespace: parts, barriers,
commands, faults, diagnostics) whose steps the plant drives. A stepping thread meets the
neighbours, then steps the cell with a :class:`~conveyor_twin.coord.runner.Runner` as far as
the conservative rule allows (:class:`~conveyor_twin.plant.stepping.CellStepping`: the rule is
the runner's gate), publishes the links' batches every sync period and whenever it has to
wait, and waits for the neighbours' batches; executor callbacks hand incoming batches to the
link ends. After its last step a cell sends
its entries' final batches and reports ``done`` once every exit heard its entry cell's final
batch (:meth:`PlantCellNode.settled`): the cells' done reports agree, and the ledger built from
them balances exactly.

Topics (relative to the plant's namespace, :data:`~conveyor_twin.contract.PLANT`):
``links/<link>/transfer`` (the exit's :class:`~conveyor_twin.plant.link.Departures`),
``links/<link>/accepted`` (the entry's :class:`~conveyor_twin.plant.link.Acceptances`),
``progress`` (every cell's counts).

A failure of the stepping thread or of a link's callback is reported once to the node's
:attr:`~PlantCellNode.health` (the cell twin's, with streams: its diagnostics say ERROR) and
ends the cell's run with :attr:`~PlantCellNode.error` set.
"""

from pathlib import Path
import threading
import time
from typing import Any, Callable, Dict, List, Optional

from rclpy._rclpy_pybind11 import RCLError
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.node import Node

from conveyor_twin import contract
from conveyor_twin.coord.clock import step_ns
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import StepStats, TimeMode
from conveyor_twin.health import Health
from conveyor_twin.plant.cell import PlantCellCore
from conveyor_twin.plant.model import Plant
from conveyor_twin.plant.stepping import CellStepping, sync_period
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.plant_messages import (CellProgress, PartTransfer, TransferAccepted,
                                              acceptances_msg, acceptances_of, departures_msg,
                                              departures_of, progress_msg)
from conveyor_twin.ros.qos import to_rclpy

#: Longest wait for the neighbours before and after the stepping before looking again [s].
WAIT_PERIOD = 0.05
#: Shortest wall time between two ``progress`` reports of a cell (but the last) [s].
PROGRESS_PERIOD = 0.2
#: After its last step, a cell waits for the final batch of each exit's entry cell; an entry
#: cell with no publisher on the link for this long is gone, and the link keeps its parts [s].
PEER_GONE_AFTER = 3.0
#: Longest wait, when a cell stops, for every subscriber to acknowledge its last reports and
#: batches [s] (a lost datagram is sent again within a heartbeat period, well under this).
DELIVER_TIMEOUT = 3.0


def record_cell(composed: Any, plant: Plant, name: str, folder: str, mode: TimeMode) -> Any:
    """Record a plant cell's frames (every stream of its namespace) to ``folder/<name>.mcap``;
    return the :class:`~conveyor_twin.ros.run_recording.TwinRecording` (close it after the
    cell stopped). The file carries the cell file, the seed and the plant's name and file.

    :raises RecordingError: if the file cannot be created.
    """
    from conveyor_twin.cell.loader import default_cell_text
    from conveyor_twin.record.writer import McapRecorder
    from conveyor_twin.ros.run_recording import TwinRecording
    spec = plant.cell(name)
    source = spec.cell.source_file
    try:
        with open(source, encoding='utf-8') as f:
            text = f.read()
    except OSError:
        text = default_cell_text()
    Path(folder).mkdir(parents=True, exist_ok=True)
    recorder = McapRecorder(
        str(Path(folder) / f'{name}.mcap'), cell_yaml=text, seed=spec.seed,
        step_ns=step_ns(plant.step),
        metadata={'recorded_by': 'conveyor-twin plant', 'plant': plant.name,
                  'plant_file': plant.source_file, 'plant_cell': name,
                  'namespace': '/' + spec.namespace, 'mode': mode.value},
        health=composed.health)
    try:
        return TwinRecording(composed, recorder)
    except BaseException:
        recorder.close()
        raise


class PlantCellNode:
    """One cell of a plant in this process, coupled to its neighbours over ROS topics.

    :param plant: the validated plant. :param name: the cell to run.
    :param context: an initialised rclpy Context.
    :param mode: realtime (paced by the wall clock), fast, or lockstep (one step ahead of the
        neighbours at most, batches every step).
    :param end_step: the step to run to (0: until :meth:`stop`).
    :param run: id of this run of the cell (give a restarted cell another).
    :param streams: serve the cell's own interface (parts, barriers, commands, ...).
    :param record: folder to record the cell's streams to (``<cell>.mcap``; with streams).
    :param plc: the cell's PLC servers (:class:`~conveyor_twin.plc.options.PlcOptions`, the
        ports of this cell; with streams); the plant steps the cell, so a PLC cannot.

    A failure of the stepping thread, the executor or a link's callback is reported once to
    :attr:`health` (with streams the cell twin's: its diagnostics say ERROR), sets
    :attr:`error` and ends the run (:attr:`done`).
    """

    def __init__(self, plant: Plant, name: str, *, context: Context, mode: TimeMode,
                 end_step: int = 0, run: int = 0, streams: bool = True,
                 record: str = '', plc: Optional[Any] = None) -> None:
        self.plant = plant
        self.mode = TimeMode(mode)
        self.end_step = int(end_step)
        spec = plant.cell(name)
        self.composed = None
        twin = None
        if streams:
            from conveyor_twin.ros.compose import ComposedTwin
            self.composed = ComposedTwin(spec.cell, seed=spec.seed, mode=TimeMode.LOCKSTEP,
                                         context=context, namespace='/' + spec.namespace)
            self.composed.runner.step = self._refuse_step
            if self.composed.sim_interfaces is not None:  # queries only: the plant steps it
                self.composed.sim_interfaces.refuse_control(
                    'the plant steps, resets and fills this cell')
            if plc is not None and plc.any:
                self._attach_plc(plc)
            twin = self.composed.assembled
            self.executor = self.composed.executor
        else:
            self.executor = make_executor(context)
        #: Where this cell's threads and callbacks report a failure.
        self.health: Health = self.composed.health if self.composed is not None else Health()
        self.name = name
        self.recording = (record_cell(self.composed, plant, name, record, self.mode)
                          if record and self.composed is not None else None)
        self.core = PlantCellCore(plant, name, run=run, twin=twin,
                                  lockstep=self.mode is TimeMode.LOCKSTEP)
        self.period = sync_period(plant, self.mode)
        #: The cell as the runner steps it; its lock guards the link ends.
        self.stepping = CellStepping(self.core, self.health, period=self.period,
                                     sync=self._flush)
        #: Steps the cell as the rule allows (realtime: paced, as before, without the
        #: tuning of a cell twin's stepping thread).
        self.stepper = Runner(self.stepping, self.mode, max_steps=self.end_step or None,
                              gate=self.stepping, on_error=self._end,
                              name=f'plant cell {name!r}: stepping thread')
        self.stepper.tuned = self.stepper.warm_up = False
        self.stepper.listeners.append(self.stepping.stepped)
        self.lock = self.stepping.lock
        self._wake = self.stepping.wake
        self._stop = threading.Event()
        #: Set once the run completed its end step and its exits settled, or on an error.
        self.done = threading.Event()
        self.error: Optional[BaseException] = None
        self.reports: Dict[str, 'CellProgress'] = {}
        ns = '/' + plant.namespace
        self.node = Node(contract.plant_cell_node(name), namespace=ns, context=context)
        qos = to_rclpy(contract.PLANT_QOS)
        self._dep_pub = {x.link.name: self.node.create_publisher(
            PartTransfer, contract.link_topic(contract.PART_TRANSFER, ns, x.link.name), qos)
            for x in self.core.exits}
        self._acc_topic = {x.link.name: contract.link_topic(contract.TRANSFER_ACCEPTED, ns,
                                                            x.link.name) for x in self.core.exits}
        self._absent_since: Dict[str, float] = {}
        self._acc_pub = {e.link.name: self.node.create_publisher(
            TransferAccepted, contract.link_topic(contract.TRANSFER_ACCEPTED, ns, e.link.name),
            qos) for e in self.core.entries}
        self._subs = []
        for e in self.core.entries:
            self._subs.append(self.node.create_subscription(
                PartTransfer, contract.link_topic(contract.PART_TRANSFER, ns, e.link.name),
                self._receiver(e.receive, departures_of, f'link {e.link.name!r} entry'), qos))
        for x in self.core.exits:
            self._subs.append(self.node.create_subscription(
                TransferAccepted, self._acc_topic[x.link.name],
                self._receiver(x.receive, acceptances_of, f'link {x.link.name!r} exit'), qos))
        progress_qos = to_rclpy(contract.CELL_PROGRESS.qos)
        self._progress_pub = self.node.create_publisher(CellProgress,
                                                        contract.CELL_PROGRESS.name,
                                                        progress_qos)
        self._subs.append(self.node.create_subscription(CellProgress,
                                                        contract.CELL_PROGRESS.name,
                                                        self._on_progress, progress_qos))
        self._progress_at = 0.0
        self.executor.add_node(self.node)
        self._threads: List[threading.Thread] = []
        #: Publishes the middleware refused at first (and that were retried).
        self.publish_retries = 0

    def _attach_plc(self, plc: Any) -> None:
        """Serve the cell's OPC UA / Modbus TCP servers (stepped by the plant, not a PLC)."""
        from conveyor_twin.plc.attach import attach_plc
        try:
            self.composed.plc = attach_plc(self.composed, plc, steppable=False,
                                           mode=self.mode.value)
        except BaseException:
            self.composed.stop()
            raise
        self.composed.coordinator.add_counters(self.composed.plc.counters)

    def _refuse_step(self, n: int = 1) -> None:
        self.node.get_logger().warning('step service ignored: the plant steps this cell')

    def _receiver(self, take: Callable, convert: Callable, what: str) -> Callable:
        def callback(msg) -> None:
            try:
                batch = convert(msg)
                with self.lock:
                    take(batch)
            except Exception as exc:  # reported once; the run ends with it
                self.fail(what, exc)
            self._wake.set()
        return callback

    def fail(self, what: str, exc: BaseException) -> None:
        """Report a failure of ``what`` (a thread or a link's callback) to :attr:`health`
        once, and end the run with it (:attr:`error`, :attr:`done`)."""
        self.health.report(f'plant cell {self.name!r}: {what}', exc)
        self._end(exc)

    def _end(self, exc: BaseException) -> None:
        """End the run with a failure already reported."""
        if self.error is None:
            self.error = exc
        self.stepper.request_stop()
        self.done.set()
        self._wake.set()

    @property
    def stats(self) -> StepStats:
        """Durations of the cell's steps [s]."""
        return self.stepper.stats

    def _on_progress(self, msg: 'CellProgress') -> None:
        self.reports[msg.cell] = msg
        self._wake.set()

    # --- stepping -------------------------------------------------------------------------
    def _flush(self, done: bool = False) -> None:
        core = self.core
        with self.lock:
            time_ns = core.step_index * step_ns(self.plant.step)
            outgoing = [(self._dep_pub[x.link.name], departures_msg(x.batch(), time_ns))
                        for x in core.exits]
            outgoing += [(self._acc_pub[e.link.name], acceptances_msg(e.batch(), time_ns))
                         for e in core.entries]
            now = time.monotonic()
            if done or now - self._progress_at >= PROGRESS_PERIOD:
                self._progress_at = now
                outgoing.append((self._progress_pub, progress_msg(
                    core, end_step=self.end_step, done=done, stats=self.stats,
                    rtf=self.real_time_factor(), with_hash=done)))
        for pub, msg in outgoing:
            self._publish(pub, msg)

    def report_done(self) -> None:
        """Publish the batches and the final report again (for a late subscriber; ``done``
        only while the exits are settled: a restarted entry cell unsettles them)."""
        self._flush(done=self.done.is_set() and self.error is None and self.settled())

    def settled(self) -> bool:
        """True once every exit heard its entry cell's final batch (then this cell's counts of
        its links agree with the entry cells' last reports), or that cell has been gone for
        :data:`PEER_GONE_AFTER` (no publisher on the link: the link keeps its parts)."""
        now = time.monotonic()
        settled = True
        for x in self.core.exits:
            name = x.link.name
            if x.peer_final:
                self._absent_since.pop(name, None)
                continue
            if self.node.count_publishers(self._acc_topic[name]) == 0:
                since = self._absent_since.setdefault(name, now)
                if now - since >= PEER_GONE_AFTER:
                    self.node.get_logger().warning(
                        f'link {name!r}: cell {x.link.target.cell!r} is gone; the link holds '
                        f'{x.in_link} parts', once=True)
                    continue
            else:
                self._absent_since.pop(name, None)
            settled = False
        return settled

    def _settle(self) -> None:
        """After the last step: send the entries' final batches and report until every exit
        is settled (:meth:`settled`); the report that ends it is ``done``."""
        with self.lock:
            self.core.finish()
        while not self._stop.is_set() and self.error is None:
            settled = self.settled()
            self._flush(done=settled)
            if settled:
                self.done.set()
                return
            self._wake.wait(WAIT_PERIOD)
            self._wake.clear()

    def _publish(self, pub, msg) -> None:
        """Publish, retrying while the middleware refuses (a keep-all history full of samples
        a slow subscriber has not acknowledged yet): nothing of a link may be dropped."""
        while True:
            try:
                pub.publish(msg)
                return
            except RCLError:
                self.publish_retries += 1
                if self._stop.is_set():
                    raise
                time.sleep(0.01)

    def neighbours(self) -> List[str]:
        """Return the cells this one shares a link with."""
        names = {e.link.source.cell for e in self.core.entries}
        names |= {x.link.target.cell for x in self.core.exits}
        return sorted(names)

    def _meet_neighbours(self) -> None:
        """Report, and wait until every neighbour has reported once: the links' topics are
        then matched both ways, and the stepping starts together (the real-time factor
        counts stepping, not start-up)."""
        while not self._stop.is_set() and self.error is None:
            self._flush()
            if all(n in self.reports for n in self.neighbours()):
                return
            self._wake.wait(WAIT_PERIOD)
            self._wake.clear()

    def _run(self) -> None:
        """The stepping thread: meet the neighbours, step to the end, then settle."""
        try:
            self._meet_neighbours()
            self.stepper.run()
            if self.error is not None:
                return
            if self.end_step and self.core.step_index >= self.end_step:
                self._settle()
            else:
                self._flush()
        except BaseException as exc:  # reported once, never swallowed
            self.fail('stepping thread', exc)

    def real_time_factor(self) -> float:
        """Simulated over wall time of the stepping so far."""
        return self.stepper.real_time_factor()

    def neighbours_not_done(self) -> List[str]:
        """Return the neighbours (:meth:`neighbours`) that have not reported ``done``: a cell
        that is done may end once this is empty, since each neighbour has then heard its
        final batches (a neighbour is done only once settled), and other cells never need
        anything from it."""
        return [n for n in self.neighbours() if n not in self.reports
                or not self.reports[n].done]

    def describe_waiting(self) -> str:
        """Say which neighbours this done cell waits for, with their last reported step."""
        parts = []
        for n in self.neighbours_not_done():
            report = self.reports.get(n)
            parts.append(f'{n!r} (last report: step {report.step})' if report is not None
                         else f'{n!r} (no report heard)')
        return (f'cell {self.name!r} is done at step {self.core.step_index}; waiting for the '
                f'done reports of ' + ', '.join(parts))

    def _spin(self, stop: threading.Event) -> None:
        try:
            spin_until(self.executor, stop)
        except BaseException as exc:  # reported once, never swallowed
            self.fail('executor', exc)

    def start(self) -> None:
        """Start serving callbacks and the stepping thread."""
        stop_spin = self._stop
        if self.composed is not None:
            self.composed.start()
        else:
            spin = threading.Thread(target=self._spin, args=(stop_spin,),
                                    name='plant_executor', daemon=True)
            spin.start()
            self._threads.append(spin)
        stepper = threading.Thread(target=self._run, name='plant_steps', daemon=True)
        stepper.start()
        self._threads.append(stepper)

    def deliver(self, timeout: float = DELIVER_TIMEOUT) -> bool:
        """Wait until every matched subscriber acknowledged what this cell published (its
        last report and batches), at most ``timeout`` [s]; False if one did not.

        A cell that ends right after its one ``done`` report (the last cell to finish) would
        otherwise leave a subscriber whose datagram was lost waiting for that report forever:
        a writer that is gone sends nothing again."""
        deadline = time.monotonic() + timeout
        publishers = [self._progress_pub, *self._dep_pub.values(), *self._acc_pub.values()]
        for pub in publishers:
            left = max(0.0, deadline - time.monotonic())
            if not pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9))):
                return False
        return True

    def stop(self) -> None:
        """Stop stepping and serving (after the subscribers acknowledged the cell's last
        reports and batches, :meth:`deliver`); destroy the nodes."""
        self._stop.set()
        self.stepper.request_stop()
        self._wake.set()
        for t in self._threads:
            t.join(5.0)
        if not self.deliver():
            self.node.get_logger().warning(
                f'a subscriber did not acknowledge the last reports of cell {self.name!r} '
                f'within {DELIVER_TIMEOUT:g} s (gone, or too slow)')
        if self.composed is not None:
            self.composed.stop()
        else:
            self.executor.shutdown(timeout_sec=5.0)
        if self.recording is not None:
            self.recording.close()
        self.node.destroy_node()
