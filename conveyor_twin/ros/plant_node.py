"""Cells of a plant over ROS 2: one node per cell, the links' batches on topics.

:class:`PlantCellNode` runs one cell (:class:`~conveyor_twin.plant.cell.PlantCellCore`) in this
process: with ``streams`` the cell's whole interface (a lockstep
:class:`~conveyor_twin.ros.compose.ComposedTwin` under the cell's namespace: parts, barriers,
commands, faults, diagnostics) whose steps the plant drives. A stepping thread computes steps
as far as the conservative rule allows (:mod:`conveyor_twin.plant.sync`), publishes the links'
batches every sync period and whenever it has to wait, and waits for the neighbours' batches;
executor callbacks hand incoming batches to the link ends. After its last step a cell sends
its entries' final batches and reports ``done`` once every exit heard its entry cell's final
batch (:meth:`PlantCellNode.settled`): the cells' done reports agree, and the ledger built from
them balances exactly.

Topics (relative to the plant's namespace, :data:`~conveyor_twin.contract.PLANT`):
``links/<link>/transfer`` (the exit's :class:`~conveyor_twin.plant.link.Departures`),
``links/<link>/accepted`` (the entry's :class:`~conveyor_twin.plant.link.Acceptances`),
``progress`` (every cell's counts).

:class:`ComposedPlant` runs every cell in this process with
:class:`~conveyor_twin.plant.runner.PlantRunner` (batches handed over in memory) and publishes
the same ``progress``. :class:`PlantMonitor` builds the plant-wide ledger from ``progress`` and
publishes it on the plant's ``diagnostics`` (status ``conveyor_twin: plant``).
"""

from pathlib import Path
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence, Set, Tuple

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy._rclpy_pybind11 import RCLError
from rclpy.context import Context
from rclpy.node import Node

from conveyor_twin import contract
from conveyor_twin.coord.clock import stamp, step_ns
from conveyor_twin.coord.timing import DeadlinePacer, StepStats, TimeMode
from conveyor_twin.plant.cell import PlantCellCore
from conveyor_twin.plant.ledger import LinkCounts, PlantLedger
from conveyor_twin.plant.link import Acceptances, Departures, Transit
from conveyor_twin.plant.model import Plant
from conveyor_twin.plant.runner import PlantRunner
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.endpoints import message_class
from conveyor_twin.ros.qos import to_rclpy

PartTransfer = message_class(contract.PART_TRANSFER.type_name)
TransferAccepted = message_class(contract.TRANSFER_ACCEPTED.type_name)
CellProgress = message_class(contract.CELL_PROGRESS.type_name)

#: Longest wait of a stepping thread for its neighbours before it looks again [s].
WAIT_PERIOD = 0.05
#: Shortest wall time between two ``progress`` reports of a cell (but the last) [s].
PROGRESS_PERIOD = 0.2
#: After its last step, a cell waits for the final batch of each exit's entry cell; an entry
#: cell with no publisher on the link for this long is gone, and the link keeps its parts [s].
PEER_GONE_AFTER = 3.0


def sync_period(plant: Plant, mode: TimeMode) -> int:
    """Return the steps between two publications of a cell's batches: a quarter of the
    shortest link delay (so neighbours rarely wait), 1 in lockstep."""
    if mode is TimeMode.LOCKSTEP:
        return 1
    return max(1, plant.min_delay // 4)


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
                  'namespace': '/' + spec.namespace, 'mode': mode.value})
    try:
        return TwinRecording(composed, recorder)
    except BaseException:
        recorder.close()
        raise


# --- batches <-> messages (pure conversions) -----------------------------------------------
def departures_msg(batch: Departures, time_ns: int) -> 'PartTransfer':
    """Return the ``PartTransfer`` message of a batch of departures."""
    m = PartTransfer()
    m.header.stamp.sec, m.header.stamp.nanosec = stamp(time_ns)
    m.header.frame_id = batch.link
    m.link, m.through = batch.link, batch.through
    m.first_seq, m.held_from = batch.first_seq, batch.held_from
    m.run = batch.run
    p = batch.parts
    m.step_left = [t.step for t in p]
    m.id = [t.id for t in p]
    m.origin_id = [t.origin for t in p]
    m.part_type = [t.part_type for t in p]
    m.x, m.y, m.yaw = [t.x for t in p], [t.y for t in p], [t.yaw for t in p]
    m.vx, m.vy, m.wz = [t.vx for t in p], [t.vy for t in p], [t.wz for t in p]
    return m


def departures_of(m: 'PartTransfer') -> Departures:
    """Return the batch of departures a ``PartTransfer`` message carries."""
    parts = [Transit(m.first_seq + i, int(s), int(pid), int(o), int(t), float(x), float(y),
                     float(a), float(vx), float(vy), float(w))
             for i, (s, pid, o, t, x, y, a, vx, vy, w) in enumerate(zip(
                 m.step_left, m.id, m.origin_id, m.part_type, m.x, m.y, m.yaw, m.vx, m.vy,
                 m.wz))]
    return Departures(m.link, int(m.through), int(m.first_seq), int(m.held_from), parts,
                      int(m.run))


def acceptances_msg(batch: Acceptances, time_ns: int) -> 'TransferAccepted':
    """Return the ``TransferAccepted`` message of a batch of acceptances."""
    m = TransferAccepted()
    m.header.stamp.sec, m.header.stamp.nanosec = stamp(time_ns)
    m.header.frame_id = batch.link
    m.link, m.through, m.run = batch.link, batch.through, batch.run
    m.seq, m.step = list(batch.seq), list(batch.step)
    m.starting = batch.starting
    m.exit_run_known = batch.exit_run is not None
    m.exit_run = batch.exit_run if batch.exit_run is not None else 0
    m.final = batch.final
    return m


def acceptances_of(m: 'TransferAccepted') -> Acceptances:
    """Return the batch of acceptances a ``TransferAccepted`` message carries."""
    return Acceptances(m.link, int(m.through), int(m.run), [int(s) for s in m.seq],
                       [int(s) for s in m.step], starting=bool(m.starting),
                       exit_run=int(m.exit_run) if m.exit_run_known else None,
                       final=bool(m.final))


def progress_msg(core: PlantCellCore, *, end_step: int, done: bool, stats: StepStats,
                 rtf: float, with_hash: bool) -> 'CellProgress':
    """Return a ``CellProgress`` message of a cell now (``with_hash``: its state digest)."""
    m = CellProgress()
    s = core.step_index
    m.header.stamp.sec, m.header.stamp.nanosec = stamp(s * step_ns(core.plant.step))
    m.header.frame_id = core.name
    m.cell, m.step, m.end_step, m.done = core.name, s, end_step, done
    m.run = core.run
    c = core.counts()
    m.entered, m.in_cell, m.left, m.vanished = (c['entered'], c['in_cell'], c['left'],
                                                c['vanished'])
    m.exit_link = [x.link.name for x in core.exits]
    m.exit_sent = [x.sent for x in core.exits]
    m.exit_accepted = [x.accepted for x in core.exits]
    m.exit_resent = [x.resent for x in core.exits]
    m.entry_link = [e.link.name for e in core.entries]
    m.entry_inserted = [e.inserted for e in core.entries]
    m.entry_waiting = list(core.waiting)
    m.entry_earlier = [e.earlier for e in core.entries]
    m.entry_dropped = [e.dropped for e in core.entries]
    m.step_time_mean_ms = stats.total()['mean_ms'] if stats.count else 0.0
    m.real_time_factor = rtf
    m.state_hash = core.state_hash() if with_hash else ''
    return m


def ledger_of(reports: Dict[str, 'CellProgress'],
              ended: Sequence['CellProgress'] = ()) -> PlantLedger:
    """Return the plant-wide ledger from the latest report of every cell and the last reports
    of cell runs that ended (a process killed or restarted).

    A link's parts are as its exit cell's current run reports them: sent, and inserted as the
    entry reported to the exit (the rest the exit still holds). A run that ended keeps what
    entered and left through it; what it held is ``lost``:

    - what was in the cell at its last report;
    - as an entry cell: what it inserted and reported to the exit after that report (what it
      inserted and did not report, the exit still holds and sends to the next run);
    - as an exit cell: what it sent by its last report less what the entry inserted of the
      parts of ended runs (the rest the entry dropped, or never received).

    If that sum is negative for a cell (parts that entered a source cell after its last
    report reached the next cell), it counts as entered instead. Exact for the cells' done
    reports (settled: every exit heard its entry's final batch) and one restarted cell per
    link at a time; while cells run, a link's counts may lag its entry cell's by a batch.
    """
    cells: Dict[str, Dict[str, float]] = {}
    reported: Dict[str, int] = {}      # per link: insertions of the current exit run's parts
    earlier: Dict[str, int] = {}       # per link: insertions of ended exit runs' parts
    waiting: Dict[str, int] = {}
    net: Dict[str, float] = {}         # per cell with ended runs: what they held
    ended_links: Dict[str, str] = {}   # link -> its entry cell, for ended entry runs
    ended_sent: Dict[str, int] = {}    # link -> sent by ended exit runs
    ended_exit: Dict[str, str] = {}    # link -> its exit cell, for ended exit runs
    for m in (*ended, *reports.values()):
        current = reports.get(m.cell) is m
        key = m.cell if current else f'{m.cell}#{m.run}'
        cells[key] = {'entered': m.entered, 'in_cell': m.in_cell if current else 0.0,
                      'left': m.left, 'vanished': m.vanished}
        if not current:
            net[m.cell] = net.get(m.cell, 0.0) + m.in_cell
            ended_links.update((name, m.cell) for name in m.entry_link)
            for name, sent in zip(m.exit_link, m.exit_sent):
                ended_sent[name] = ended_sent.get(name, 0) + int(sent)
                ended_exit[name] = m.cell
        for name, n, w, e in zip(m.entry_link, m.entry_inserted, m.entry_waiting,
                                 m.entry_earlier or [0] * len(m.entry_link)):
            reported[name] = reported.get(name, 0) + int(n) - int(e)
            earlier[name] = earlier.get(name, 0) + int(e)
            if current:
                waiting[name] = int(w)
    links = {}
    for m in reports.values():
        for name, sent, acc, res in zip(m.exit_link, m.exit_sent, m.exit_accepted,
                                        m.exit_resent):
            links[name] = LinkCounts(int(sent), int(acc), waiting.get(name, 0), int(res))
            if name in ended_links:
                cell = ended_links[name]
                net[cell] += max(0, int(acc) - reported.get(name, 0))
    for name, cell in ended_exit.items():
        net[cell] += ended_sent[name] - earlier.get(name, 0)
    lost = 0.0
    for cell, held in net.items():
        if held >= 0:
            lost += held
        else:
            cells[f'{cell}#unreported'] = {'entered': -held, 'in_cell': 0.0, 'left': 0.0,
                                           'vanished': 0.0}
    return PlantLedger(cells, links, lost)


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
    """

    def __init__(self, plant: Plant, name: str, *, context: Context, mode: TimeMode,
                 end_step: int = 0, run: int = 0, streams: bool = True,
                 record: str = '') -> None:
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
            twin = self.composed.assembled
            self.executor = self.composed.executor
        else:
            self.executor = make_executor(context)
        self.recording = (record_cell(self.composed, plant, name, record, self.mode)
                          if record and self.composed is not None else None)
        self.core = PlantCellCore(plant, name, run=run, twin=twin,
                                  lockstep=self.mode is TimeMode.LOCKSTEP)
        self.period = sync_period(plant, self.mode)
        self.stats = StepStats()
        self.lock = threading.Lock()
        self._wake = threading.Event()
        self._stop = threading.Event()
        #: Set once the run completed its end step and its exits settled, or on an error.
        self.done = threading.Event()
        self.error: Optional[BaseException] = None
        self.reports: Dict[str, 'CellProgress'] = {}
        ns = '/' + plant.namespace
        self.node = Node(f'plant_{name}', namespace=ns, context=context)
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
                self._receiver(e.receive, departures_of), qos))
        for x in self.core.exits:
            self._subs.append(self.node.create_subscription(
                TransferAccepted, self._acc_topic[x.link.name],
                self._receiver(x.receive, acceptances_of), qos))
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
        self.wall_start = self.wall_end = 0.0
        #: Publishes the middleware refused at first (and that were retried).
        self.publish_retries = 0

    def _refuse_step(self, n: int = 1) -> None:
        self.node.get_logger().warning('step service ignored: the plant steps this cell')

    def _receiver(self, take: Callable, convert: Callable) -> Callable:
        def callback(msg) -> None:
            batch = convert(msg)
            with self.lock:
                take(batch)
            self._wake.set()
        return callback

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
        while not self._stop.is_set():
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
        while not self._stop.is_set():
            self._flush()
            if all(n in self.reports for n in self.neighbours()):
                return
            self._wake.wait(WAIT_PERIOD)
            self._wake.clear()

    def _loop(self) -> None:
        core = self.core
        pacer = DeadlinePacer(step_ns(self.plant.step))
        realtime = self.mode is TimeMode.REALTIME
        end = self.end_step or (1 << 62)
        since = 0
        self._meet_neighbours()
        self.wall_start = time.monotonic()
        pacer.restart()
        try:
            while not self._stop.is_set() and core.step_index < end:
                with self.lock:
                    ready = core.may_step()
                    if ready:
                        t0 = time.perf_counter()
                        core.step()
                        self.stats.add(time.perf_counter() - t0)
                if ready:
                    since += 1
                    if since >= self.period:
                        self._flush()
                        since = 0
                    if realtime:
                        pacer.wait_next()
                    continue
                self._flush()
                since = 0
                self._wake.wait(WAIT_PERIOD)
                self._wake.clear()
            self.wall_end = time.monotonic()
            if core.step_index >= end:
                self._settle()
            else:
                self._flush()
        except BaseException as exc:  # reported by the caller, never swallowed
            self.error = exc
            self.node.get_logger().error(f'cell {core.name!r} stopped: {exc!r}')
            self.done.set()

    def real_time_factor(self) -> float:
        """Simulated over wall time of the stepping so far."""
        end = self.wall_end or time.monotonic()
        wall = end - self.wall_start if self.wall_start else 0.0
        return self.core.step_index * self.plant.step / wall if wall > 0 else 0.0

    def all_done(self) -> bool:
        """True once every cell of the plant reported it completed the end step."""
        names = [c.name for c in self.plant.cells]
        return all(n in self.reports and self.reports[n].done for n in names)

    def start(self) -> None:
        """Start serving callbacks and the stepping thread."""
        stop_spin = self._stop
        if self.composed is not None:
            self.composed.start()
        else:
            spin = threading.Thread(target=spin_until, args=(self.executor, stop_spin),
                                    name='plant_executor', daemon=True)
            spin.start()
            self._threads.append(spin)
        stepper = threading.Thread(target=self._loop, name='plant_steps', daemon=True)
        stepper.start()
        self._threads.append(stepper)

    def stop(self) -> None:
        """Stop stepping and serving; destroy the nodes."""
        self._stop.set()
        self._wake.set()
        for t in self._threads:
            t.join(5.0)
        if self.composed is not None:
            self.composed.stop()
        else:
            self.executor.shutdown(timeout_sec=5.0)
        if self.recording is not None:
            self.recording.close()
        self.node.destroy_node()


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
            self.node.get_logger().error(f'plant stopped: {exc!r}')
        finally:
            self.done.set()

    def all_done(self) -> bool:
        """True once the plant completed the end step."""
        return self.done.is_set()

    def start(self) -> None:
        """Start serving callbacks and the stepping thread."""
        for ct in self.composed.values():
            ct.start()
        spin = threading.Thread(target=spin_until, args=(self.executor, self._stop),
                                name='plant_executor', daemon=True)
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


class PlantMonitor:
    """The plant-wide view: every cell's latest ``progress``, the ledger, and the plant's
    ``diagnostics`` (status ``conveyor_twin: plant``).

    :param plant: the validated plant. :param context: an initialised rclpy Context.
    """

    def __init__(self, plant: Plant, *, context: Context) -> None:
        self.plant = plant
        self.reports: Dict[str, 'CellProgress'] = {}
        #: The last report of every cell run that ended (another run of the cell reported).
        self.ended: List['CellProgress'] = []
        self._ended_runs: Set[Tuple[str, int]] = set()
        self.node = Node('plant_monitor', namespace='/' + plant.namespace, context=context)
        self._sub = self.node.create_subscription(CellProgress, contract.CELL_PROGRESS.name,
                                                  self._on_progress,
                                                  to_rclpy(contract.CELL_PROGRESS.qos))
        self._diag = self.node.create_publisher(DiagnosticArray,
                                                contract.PLANT_DIAGNOSTICS.name,
                                                to_rclpy(contract.PLANT_DIAGNOSTICS.qos))

    def _on_progress(self, msg: 'CellProgress') -> None:
        if (msg.cell, msg.run) in self._ended_runs:
            return  # a late report of a run that ended
        old = self.reports.get(msg.cell)
        if old is not None and old.run != msg.run:
            self.ended.append(old)
            self._ended_runs.add((old.cell, old.run))
        self.reports[msg.cell] = msg

    def ledger(self) -> PlantLedger:
        """Return the plant-wide ledger from the latest reports."""
        return ledger_of(dict(self.reports), list(self.ended))

    def steps(self) -> Dict[str, int]:
        """Return every cell's last reported step (-1: no report yet)."""
        return {c.name: int(self.reports[c.name].step) if c.name in self.reports else -1
                for c in self.plant.cells}

    def all_done(self) -> bool:
        """True once every cell reported it completed the end step."""
        return all(c.name in self.reports and self.reports[c.name].done
                   for c in self.plant.cells)

    def publish_diagnostics(self) -> None:
        """Publish the ledger and every cell's step as the ``conveyor_twin: plant`` status."""
        ledger = self.ledger()
        values = {k: f'{v:g}' for k, v in ledger.as_dict().items()}
        steps = self.steps()
        values.update({f'cell_{k}_step': str(v) for k, v in steps.items()})
        lowest = min(steps.values()) if steps else 0
        ok = ledger.residual == 0.0 or not self.all_done()
        status = DiagnosticStatus(
            level=DiagnosticStatus.OK if ok else DiagnosticStatus.WARN,
            name='conveyor_twin: plant', hardware_id=self.plant.name,
            message=(f'{len(steps)} cells, slowest at step {lowest}; in links '
                     f'{ledger.in_links}'),
            values=[KeyValue(key=k, value=v) for k, v in values.items()])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp.sec, msg.header.stamp.nanosec = stamp(
            max(lowest, 0) * step_ns(self.plant.step))
        self._diag.publish(msg)

    def destroy(self) -> None:
        """Destroy the node."""
        self.node.destroy_node()
