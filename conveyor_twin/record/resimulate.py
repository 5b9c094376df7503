"""Re-run a recording's cell and compare every recorded message bit for bit.

A recording of ``conveyor-twin run --record`` is self-contained: the cell description
(attachment ``cell.yaml``), the seed, the step, the namespace and the markers rate (metadata
``conveyor_twin``) and every accepted command with the step at which it took effect. This module
rebuilds the twin's cores from them (no ROS: the stages, the coordinator core and the twin's
output), schedules the commands at their steps, collects the frames the output builds and
steps the core on demand while reading the recording in file order: the recorded message with
sequence number ``s`` on a topic is compared with the ``s``-th message of that topic in the
re-run's frames (sequence numbers count every message offered, so decimation and queue drops
only skip). A closed recording is read in log-time order, which within a step need not be the
order of the sequence numbers: a step's ``light_barrier_edges`` are published micro barriers
first, then those in macro zones, then those of faults, each stamped with its own time. So the
re-run's messages are matched by their number, whatever the order they are read in; one is
dropped unmatched only once a message of its topic with a later number, stamped more than a step
after it, has been read (no recorded message can match it then).

``markers`` are matched by their stamp, not their number: the micro node builds them off the
stepping thread and, under load, publishes only the latest due one, so which steps have markers
depends on the wall clock; the re-run builds the markers of every due step on the stepping
thread with the same :class:`~conveyor_twin.output.markers.CellMarkers` and the recorded ones
must be among them, byte for byte. ``diagnostics`` are not compared: they carry wall-clock step
times. Parts placed through the
``spawn_parts`` service are recorded with the step after which they were placed and placed again
at that point; a recording with a ``reset`` call is refused (the run's time restarts at 0).
"""

from collections import Counter, deque
from dataclasses import dataclass, field
import math
from typing import Any, Deque, Dict, List, Optional, Tuple

from conveyor_twin.cell import CellError, load_cell_text
from conveyor_twin.contract import DIAGNOSTICS, FAULTS, MARKERS, STREAMS
from conveyor_twin.coord.commands import CommandRejected
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.markers import CellMarkers
from conveyor_twin.output.producers import CoordinatorOutput, MacroOutput, MicroOutput
from conveyor_twin.faults.book import CLEAR, FaultEvent, INJECT
from conveyor_twin.faults.model import FaultSpec, validate
from conveyor_twin.faults.scenario import scenario_from_text, ScenarioError
from conveyor_twin.record import reader
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.topics import resolve
from conveyor_twin.record.writer import (ACCEPTED_ACTUATOR_COMMANDS, ACCEPTED_BELT_COMMANDS,
                                         ACCEPTED_RESETS, ACCEPTED_SPAWNS)
from conveyor_twin.wire import cdr
from conveyor_twin.wire.decoders import decode_fault_state
from conveyor_twin.wire.schemas import SCHEMAS

#: Topics never compared (by contract name): their content depends on the wall clock.
NOT_COMPARED = (DIAGNOSTICS.name,)


@dataclass
class Difference:
    """The first recorded message the re-run does not reproduce."""

    topic: str
    sequence: int
    step: int
    log_time: int
    byte_offset: Optional[int]
    field: str
    recorded: str
    resimulated: str

    def __str__(self) -> str:
        where = '' if self.byte_offset is None else f', byte offset {self.byte_offset}'
        what = f': field {self.field}: recorded {self.recorded}, re-simulated ' \
            f'{self.resimulated}' if self.field else f': {self.recorded}'
        return (f'{self.topic} message #{self.sequence} (step {self.step}, log time '
                f'{self.log_time} ns){where}{what}')


@dataclass
class ResimReport:
    """What a re-simulation compared and the first difference, if any."""

    path: str
    steps: int = 0
    commands: int = 0
    spawns: int = 0
    faults: int = 0
    compared: Dict[str, int] = field(default_factory=Counter)
    skipped: Dict[str, int] = field(default_factory=Counter)
    complete_source: bool = True
    difference: Optional[Difference] = None

    @property
    def ok(self) -> bool:
        """True if every compared message was identical."""
        return self.difference is None

    def as_dict(self) -> Dict[str, Any]:
        """Return the report as plain data (JSON)."""
        d = self.difference
        return {'path': self.path, 'ok': self.ok, 'steps': self.steps,
                'commands': self.commands, 'spawns': self.spawns, 'faults': self.faults,
                'compared': dict(self.compared),
                'compared_total': sum(self.compared.values()),
                'not_compared': dict(self.skipped), 'complete_source': self.complete_source,
                'difference': None if d is None else {**vars(d), 'text': str(d)}}


def _meta(path: str) -> Dict[str, str]:
    meta = reader.read_metadata(path).get('conveyor_twin')
    if not meta:
        raise RecordingError(f'{path}: no conveyor_twin metadata record: not a recording of '
                             'conveyor-twin run --record, cannot re-simulate')
    for key in ('seed', 'step_ns'):
        if not meta.get(key, '').strip().lstrip('-').isdigit():
            raise RecordingError(f'{path}: metadata conveyor_twin.{key} = '
                                 f'{meta.get(key, "")!r}: expected an integer')
    return meta


def _field_difference(type_name: str, a: bytes, b: bytes) -> Tuple[str, str, str]:
    """Return (field path, recorded value, re-simulated value) of the first differing field."""
    try:
        from mcap_ros2._dynamic import generate_dynamic
        decode = generate_dynamic(type_name, SCHEMAS[type_name])[type_name]
        x, y = decode(a), decode(b)
    except Exception:  # noqa: BLE001 - an undecodable message: the byte offset must do
        return '', '', ''
    return _walk(x, y, '') or ('', '', '')


def _walk(x: Any, y: Any, path: str) -> Optional[Tuple[str, str, str]]:
    slots = getattr(x, '__slots__', None)
    if slots is not None and type(x) is type(y):
        for name in slots:
            found = _walk(getattr(x, name), getattr(y, name), f'{path}.{name}' if path else name)
            if found:
                return found
        return None
    if isinstance(x, (list, tuple, bytes, bytearray)) and isinstance(y, (list, tuple, bytes,
                                                                          bytearray)):
        for i, (u, v) in enumerate(zip(x, y)):
            found = _walk(u, v, f'{path}[{i}]')
            if found:
                return found
        if len(x) != len(y):
            return f'{path} (length)', str(len(x)), str(len(y))
        return None
    if hasattr(x, 'tolist') and hasattr(y, 'tolist'):
        return _walk(x.tolist(), y.tolist(), path)
    same = x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x)
                      and math.isnan(y) and repr(x) == repr(y))
    return None if same else (path, repr(x), repr(y))


_MARKER_TYPE = 'visualization_msgs/msg/MarkerArray'
_decoders: Dict[str, Any] = {}


def _marker_stamp(data: bytes) -> Optional[int]:
    """Return the latest header stamp of a MarkerArray's markers [ns] (the time it was built
    for: static markers are stamped 0), or None if it has none or cannot be decoded."""
    try:
        decode = _decoders.get(_MARKER_TYPE)
        if decode is None:
            from mcap_ros2._dynamic import generate_dynamic
            decode = _decoders[_MARKER_TYPE] = generate_dynamic(
                _MARKER_TYPE, SCHEMAS[_MARKER_TYPE])[_MARKER_TYPE]
        stamps = [mk.header.stamp.sec * 1_000_000_000 + mk.header.stamp.nanosec
                  for mk in decode(data).markers]
    except Exception:  # noqa: BLE001 - then the log time must do
        return None
    return max(stamps) if stamps else None


def _first_byte(a: bytes, b: bytes) -> int:
    for i, (u, v) in enumerate(zip(a, b)):
        if u != v:
            return i
    return min(len(a), len(b))


class _Rerun:
    """The cores of a recording's cell, stepped on demand, with the frames they emit."""

    def __init__(self, cell: Any, seed: int) -> None:
        built = self.built = build_twin(cell, seed=seed)
        self.micro, self.macro, self.twin = built.micro, built.macro, built.twin
        self.output = TwinOutput([CoordinatorOutput(self.twin), MicroOutput(self.micro),
                                  MacroOutput(self.macro)])
        self.twin.step_listeners.append(self.output.on_step)


def resimulate(path: str, *, context: Any = None) -> ResimReport:
    """Re-run the recording's cell with its seed and commands; compare every message.

    :param path: a recording made by ``conveyor-twin run --record`` (closed or killed).
    :param context: not used (re-simulation runs the cores without ROS); accepted so that
        callers passing an rclpy Context keep working.
    :return: the report; ``report.difference`` is the first mismatch.
    :raises RecordingError: if the file is not readable or not self-contained (the message
        names the file and what is missing or invalid).
    """
    path = str(path)
    meta = _meta(path)
    seed, step_ns = int(meta['seed']), int(meta['step_ns'])
    try:
        cell_text = reader.read_attachment(path, 'cell.yaml').decode('utf-8')
        cell = load_cell_text(cell_text, f'{path}:cell.yaml')
    except (CellError, UnicodeDecodeError) as exc:
        raise RecordingError(f'{path}: attachment cell.yaml is not a valid cell: {exc}') from None
    try:
        markers_rate = float(meta.get('markers_rate', '30.0'))
    except ValueError:
        raise RecordingError(f'{path}: metadata conveyor_twin.markers_rate = '
                             f'{meta["markers_rate"]!r}: expected a number') from None
    namespace = meta.get('namespace', '')
    report = ResimReport(path, complete_source=reader.is_complete(path))
    rerun = _Rerun(cell, seed)
    if rerun.twin.dt_ns != step_ns:
        raise RecordingError(f'{path}: metadata step_ns {step_ns} differs from the step of '
                             f'cell.yaml ({rerun.twin.dt_ns} ns)')
    _schedule(path, rerun.twin, step_ns, report)
    if not _schedule_faults(path, rerun.twin, cell, namespace, step_ns, report) \
            and meta.get('scenario'):
        _arm_scenario(path, rerun, cell, meta)
    spawns = _spawns(path, cell, step_ns, report)
    markers = _build_markers(rerun, cell, markers_rate)
    _compare(path, rerun, namespace, step_ns, report, markers, spawns)
    return report


def _schedule(path: str, twin: Any, step_ns: int, report: ResimReport) -> None:
    book = twin.commands
    for m in reader.read_messages(path, topics=[ACCEPTED_BELT_COMMANDS,
                                                ACCEPTED_ACTUATOR_COMMANDS], linear=True):
        try:  # with the sender and sequence it carried ('', 0 if recorded without them)
            if m.topic == ACCEPTED_BELT_COMMANDS:
                command = book.validate_belt(*cdr.decode_belt_command(m.data),
                                             *cdr.decode_command_origin(m.data, 'BeltCommand'))
            else:
                command = book.validate_actuator(
                    *cdr.decode_actuator_command(m.data),
                    *cdr.decode_command_origin(m.data, 'ActuatorCommand'))
        except (CommandRejected, ValueError) as exc:
            raise RecordingError(f'{path}: recorded command #{m.sequence} on {m.topic} '
                                 f'(log time {m.log_time} ns) cannot be applied: {exc}') from None
        if m.log_time % step_ns or m.log_time <= 0:
            raise RecordingError(f'{path}: recorded command #{m.sequence} on {m.topic} has log '
                                 f'time {m.log_time} ns, not a step time (step {step_ns} ns)')
        book.schedule(m.log_time // step_ns, command)
        report.commands += 1


def _schedule_faults(path: str, twin: Any, cell: Any, namespace: str, step_ns: int,
                     report: ResimReport) -> bool:
    """Schedule the faults the recording's ``faults`` stream shows injected and cleared, at
    their steps with their ids; return False if the stream was not recorded."""
    topic = resolve(FAULTS.name, namespace)
    known: Dict[int, Any] = {}
    seen = False
    for m in reader.read_messages(path, topics=[topic], linear=True):
        seen = True
        try:
            state = decode_fault_state(m.data)
            step = state.stamp_ns // step_ns
            for entry in state.active:
                if entry.id in state.injected:
                    spec = FaultSpec(entry.kind, entry.target, dict(entry.params),
                                     entry.duration, entry.part_type)
                    known[entry.id] = validate(cell, spec, entry.id)
                    twin.faults.schedule(FaultEvent(step, INJECT, known[entry.id], 'recorded'))
                    report.faults += 1
            for fault_id, reason in zip(state.cleared, state.cleared_reason):
                if reason != 'expired':  # expiry follows from the duration
                    twin.faults.schedule(FaultEvent(step, CLEAR, known[fault_id], reason))
        except (ValueError, KeyError) as exc:  # CdrError, FaultRejected, an unknown id
            raise RecordingError(f'{path}: recorded fault state #{m.sequence} on {topic} '
                                 f'cannot be replayed: {exc}') from None
    return seen


def _arm_scenario(path: str, rerun: '_Rerun', cell: Any, meta: Dict[str, str]) -> None:
    """Arm the recorded scenario (a recording without the ``faults`` stream)."""
    try:
        scenario = scenario_from_text(meta['scenario'], cell, f'{path}:scenario')
    except ScenarioError as exc:
        raise RecordingError(f'{path}: metadata conveyor_twin.scenario: {exc}') from None
    rerun.built.arm_scenario(scenario)


def _spawns(path: str, cell: Any, step_ns: int,
            report: ResimReport) -> Dict[int, List[Tuple[int, Any, Any, Any]]]:
    """Return the recorded ``spawn_parts`` calls by the step after which they were placed.

    :raises RecordingError: for a recorded ``reset`` (not re-simulable) or a malformed call.
    """
    for m in reader.read_messages(path, topics=[ACCEPTED_RESETS], linear=True):
        raise RecordingError(f'{path}: the run was reset (call #{m.sequence} at log time '
                             f'{m.log_time} ns); runs with reset calls cannot be re-simulated')
    calls: Dict[int, List[Tuple[int, Any, Any, Any]]] = {}
    for m in reader.read_messages(path, topics=[ACCEPTED_SPAWNS], linear=True):
        try:
            name, x, y, yaw = cdr.decode_spawn_request(m.data)
            type_index = cell.part_type_index(name)
        except (cdr.CdrError, KeyError) as exc:
            raise RecordingError(f'{path}: recorded spawn_parts call #{m.sequence} cannot be '
                                 f'applied: {exc}') from None
        if m.log_time % step_ns or m.log_time < 0:
            raise RecordingError(f'{path}: recorded spawn_parts call #{m.sequence} has log '
                                 f'time {m.log_time} ns, not a step time (step {step_ns} ns)')
        calls.setdefault(m.log_time // step_ns, []).append((type_index, x, y, yaw))
        report.spawns += 1
    return calls


def _build_markers(rerun: _Rerun, cell: Any, markers_rate: float) -> Dict[int, bytes]:
    """Build the MarkerArray of every due step on the stepping thread; return {stamp: bytes}."""
    built: Dict[int, bytes] = {}
    if markers_rate <= 0:
        return built
    every = max(1, round(1.0 / (markers_rate * cell.settings.step)))  # as ScaleNode
    markers, stage = CellMarkers(cell), rerun.micro

    def on_step(inp: Any, _commands: Any) -> None:
        if inp.step % every == 0:
            _, part_type, x, y = stage.parts()[:4]
            built[inp.time_ns] = markers.build(inp.time_ns, part_type, x, y,
                                               stage.barrier_blocked(), inp.actuator_position)
            while len(built) > 1000:
                del built[next(iter(built))]

    rerun.twin.step_listeners.append(on_step)
    return built


class _Collector:
    """A frame sink keeping every message of the re-run by topic as (number as recorded,
    stamp [ns], bytes), in the order of the numbers."""

    def __init__(self, names: Dict[Any, str]) -> None:
        self.names = names
        self.produced: Dict[str, Deque[Tuple[int, int, bytes]]] = {}
        self.counters: Counter = Counter()

    def on_frame(self, frame: Any) -> None:
        for topic, stamp, data in frame.messages():
            name = self.names[topic]
            self.counters[name] += 1
            self.produced.setdefault(name, deque()).append((self.counters[name], stamp, data))


def _take(queue: Deque[Tuple[int, int, bytes]], sequence: int) -> Optional[bytes]:
    """Remove and return the bytes of message ``sequence`` of ``queue`` (None: not in it)."""
    for i, (number, _, data) in enumerate(queue):
        if number == sequence:
            del queue[i]
            return data
        if number > sequence:
            break
    return None


def _compare(path: str, rerun: _Rerun, namespace: str, step_ns: int, report: ResimReport,
             markers: Dict[int, bytes],
             spawns: Dict[int, List[Tuple[int, Any, Any, Any]]]) -> None:
    specs = {resolve(t.name, namespace): t for t in STREAMS}
    collector = _Collector({t: name for name, t in specs.items()})
    produced = collector.produced
    rerun.output.subscribe(collector)
    ignored = {t for t, s in specs.items() if s.name in NOT_COMPARED}
    accepted = {ACCEPTED_BELT_COMMANDS, ACCEPTED_ACTUATOR_COMMANDS, ACCEPTED_SPAWNS,
                ACCEPTED_RESETS}
    ignored |= accepted
    core = rerun.twin
    # a closed file is read through its index (CRCs checked: damage is an error, never a
    # silent skip); a killed one linearly, as recover() would
    for m in reader.read_messages(path, linear=not report.complete_source):
        if m.topic in ignored:
            if m.topic not in accepted:
                report.skipped[m.topic] += 1
            continue
        step = m.log_time // step_ns
        if m.topic not in specs:
            raise RecordingError(f'{path}: topic {m.topic} is not published by the twin '
                                 f'(namespace {namespace!r})')
        if specs[m.topic] is MARKERS:
            if not _compare_marker(m, markers, core, step_ns, report, specs):
                return
            continue
        queue = produced.setdefault(m.topic, deque())
        limit = step + 2
        # an earlier number stamped over a step before this message is never read after it:
        # the recording was decimated or dropped it (a step's edges may come in any order)
        stale = m.log_time - step_ns
        while True:
            while queue and queue[0][0] < m.sequence and queue[0][1] < stale:
                queue.popleft()
            if collector.counters[m.topic] >= m.sequence or core.step_index > limit:
                break
            for type_index, x, y, yaw in spawns.pop(core.step_index, ()):
                rerun.micro.spawn(type_index, x, y, yaw)
            core.step(1)
            report.steps = core.step_index
            for other in produced.values():  # keep memory bounded on topics not recorded
                while len(other) > 10000:
                    other.popleft()
        data = _take(queue, m.sequence)
        if data is None:
            report.difference = Difference(
                m.topic, m.sequence, step, m.log_time, None, '',
                f'the re-run published no message #{m.sequence} on {m.topic} by step '
                f'{core.step_index}', '')
            return
        if data != m.data:
            name, recorded, resimulated = _field_difference(specs[m.topic].type_name, m.data,
                                                            data)
            report.difference = Difference(m.topic, m.sequence, step, m.log_time,
                                           _first_byte(m.data, data), name, recorded,
                                           resimulated)
            return
        report.compared[m.topic] += 1


def _compare_marker(m: Any, markers: Dict[int, bytes], core: Any, step_ns: int,
                    report: ResimReport, specs: Dict[str, Any]) -> bool:
    """Compare one recorded MarkerArray with the re-run's of the same stamp; False: differs."""
    stamp = _marker_stamp(m.data)
    stamp = m.log_time if stamp is None else stamp
    while core.time_ns < stamp:
        core.step(1)
        report.steps = core.step_index
    data = markers.pop(stamp, None)
    if data is None:
        report.difference = Difference(
            m.topic, m.sequence, stamp // step_ns, m.log_time, None, '',
            f'the re-run builds no markers stamped {stamp} ns', '')
        return False
    if data != m.data:
        name, recorded, resimulated = _field_difference(specs[m.topic].type_name, m.data, data)
        report.difference = Difference(m.topic, m.sequence, stamp // step_ns, m.log_time,
                                       _first_byte(m.data, data), name, recorded, resimulated)
        return False
    report.compared[m.topic] += 1
    return True
