"""rosbag2-compatible MCAP recorder fed from the simulation thread without blocking it.

``McapRecorder.record(topic, log_time_ns, cdr_bytes)`` only appends to a bounded in-memory
queue (decimation and the queue bound are applied there, and a full queue drops the message
and counts it per topic); a writer thread drains the queue into MCAP chunks and closes a chunk
at least every ``flush_period`` seconds of wall time and/or every ``flush_sim_period_ns`` of
simulation time. The writer thread closes a chunk every half ``flush_period``
(:data:`WRITER_FLUSH_SHARE`); should it fall behind (a stepping thread that never sleeps holds
the GIL, a loaded machine does not schedule it), the producer itself drains the queue and
closes the chunk in ``record()`` once the last flush began :data:`FORCED_FLUSH_SHARE` of the
period ago. So whatever the scheduling, everything handed to ``record()`` more than
``flush_period`` of the process's running time before a kill is in the file, and the queue never
holds more than a flush period of messages (a producer that outpaces the disk is slowed to the
disk's pace rather than losing messages). The data are not fsync'ed: a killed process loses
nothing the kernel has, a power cut may.

The file is what rosbag2's MCAP storage plugin writes: profile ``ros2``, schema encoding
``ros2msg`` with the concatenated definitions, message encoding ``cdr``, channel metadata
``offered_qos_profiles`` (YAML, metadata version 9) and ``topic_type_hash`` (RIHS01), a
``rosbag2`` metadata record with the ``serialized_metadata`` of the bag, statistics, chunk and
message indexes. log time = publish time = simulation time [ns]; ``sequence`` counts the
messages offered on a channel (1-based, before decimation), so gaps show decimation and drops.

A recording is self-contained for re-simulation: attachment ``cell.yaml`` (the cell
description), metadata record ``conveyor_twin`` (software version, seed, step length, cell
name), and every accepted command on :data:`ACCEPTED_BELT_COMMANDS` /
:data:`ACCEPTED_ACTUATOR_COMMANDS` as the original BeltCommand/ActuatorCommand CDR with
log time = the simulation time of the step at which it took effect (so the step is
``log_time // step_ns``, and the order of commands within a step is the file order). Those
topics are never decimated or dropped, and are not named like the twin's command inputs, so
replaying a recording does not drive a live twin by accident. At close, metadata record
``conveyor_twin_recorder`` stores the recorded/decimated/dropped counts per topic.
"""

from collections import deque
from dataclasses import dataclass, field
import json
import os
import threading
import time
from typing import Any, Callable, Deque, Dict, Iterable, List, Mapping, Optional, Tuple

from mcap.well_known import MessageEncoding, SchemaEncoding

from . import qos as qos_mod
from ._mcapfile import McapFile
from .errors import RecordingError
from .. import __version__
from ..cell.model import Mode
from ..health import Health
from ..wire.schemas import SCHEMAS
from ..wire.typehash import type_hash

#: Topic of the accepted belt commands (BeltCommand CDR, log time = effective step time).
ACCEPTED_BELT_COMMANDS = '/conveyor_twin/accepted/belt_command'
#: Topic of the accepted actuator commands (ActuatorCommand CDR, log time = effective step time).
ACCEPTED_ACTUATOR_COMMANDS = '/conveyor_twin/accepted/actuator_command'
#: Topic of the accepted ``spawn_parts`` calls (SpawnParts request CDR, log time = the time of
#: the last step done when the parts were placed, before the next step).
ACCEPTED_SPAWNS = '/conveyor_twin/accepted/spawn_parts'
#: Topic of the accepted ``reset`` calls (Reset request CDR, log time = the time before reset).
ACCEPTED_RESETS = '/conveyor_twin/accepted/reset'
_CALL_TYPES = {ACCEPTED_SPAWNS: 'conveyor_twin_msgs/srv/SpawnParts_Request',
               ACCEPTED_RESETS: 'conveyor_twin_msgs/srv/Reset_Request'}
#: Default chunk size [bytes] (uncompressed), as rosbag2's MCAP plugin uses.
DEFAULT_CHUNK_SIZE = 768 * 1024
#: Default wall-time flush period [s].
DEFAULT_FLUSH_PERIOD = 0.1
#: Default bound of the queue between the simulation and the writer thread [messages].
DEFAULT_QUEUE_SIZE = 20000
#: Longest sleep of the writer thread [s] while waiting for messages.
POLL_PERIOD = 0.002
#: The writer thread closes a chunk when the last flush began this share of ``flush_period`` ago.
WRITER_FLUSH_SHARE = 0.5
#: ``record()`` drains and flushes itself when the last flush began this share of
#: ``flush_period`` ago (the writer thread fell behind); the rest of the period bounds the time
#: that drain and flush take.
FORCED_FLUSH_SHARE = 0.8
#: rosbag2 metadata version written into the ``rosbag2`` metadata record.
ROSBAG2_METADATA_VERSION = 9
ROS_DISTRO = 'kilted'
#: Name under which a failed writer is reported to the twin's health.
WRITER_NAME = 'recorder writer'
LIBRARY = f'conveyor_twin/{__version__} (conveyor_twin.record, rosbag2 MCAP layout)'

_REGISTER = -1


@dataclass
class TopicStats:
    """Counters of one topic [messages]."""

    type_name: str
    offered: int = 0
    recorded: int = 0
    decimated: int = 0
    dropped: int = 0


@dataclass
class RecorderStats:
    """Counters of a recorder; ``error`` is set if the writer thread failed;
    ``forced_flushes`` counts the flushes ``record()`` made because the writer thread was
    behind."""

    path: str
    topics: Dict[str, TopicStats] = field(default_factory=dict)
    error: Optional[str] = None
    forced_flushes: int = 0

    @property
    def dropped(self) -> int:
        """Total messages dropped because the queue was full."""
        return sum(t.dropped for t in self.topics.values())

    def as_dict(self) -> Dict[str, Any]:
        """Return the counters as plain data (for JSON)."""
        return {'path': self.path, 'error': self.error, 'forced_flushes': self.forced_flushes,
                'topics': {name: dict(vars(t)) for name, t in self.topics.items()}}


class _Topic:
    __slots__ = ('index', 'name', 'type_name', 'qos', 'decimation', 'essential', 'selected',
                 'stats', 'channel_id')

    def __init__(self, index: int, name: str, type_name: str, qos: qos_mod.OfferedQos,
                 decimation: int, essential: bool, selected: bool) -> None:
        self.index = index
        self.name = name
        self.type_name = type_name
        self.qos = qos
        self.decimation = decimation
        self.essential = essential
        self.selected = selected
        self.stats = TopicStats(type_name)
        self.channel_id = 0


class Compression(Mode):
    """Chunk compression of a recording (a ``str`` Enum: members equal the option strings)."""

    LZ4 = 'lz4'
    ZSTD = 'zstd'
    NONE = 'none'

    @property
    def chunk_name(self) -> str:
        """The compression field of the MCAP chunks (``''`` for none)."""
        return '' if self is Compression.NONE else self.value


class McapRecorder:
    """Record CDR messages into a rosbag2-compatible MCAP file from a background thread."""

    def __init__(self, path: str, *, compression: str = Compression.LZ4,
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_period: Optional[float] = DEFAULT_FLUSH_PERIOD,
                 flush_sim_period_ns: Optional[int] = None,
                 queue_size: int = DEFAULT_QUEUE_SIZE,
                 topics: Optional[Iterable[str]] = None,
                 decimation: Optional[Mapping[str, int]] = None,
                 cell_yaml: Optional[str] = None, seed: Optional[int] = None,
                 step_ns: Optional[int] = None,
                 metadata: Optional[Mapping[str, str]] = None,
                 on_thread_start: Optional[Callable[[], Any]] = None,
                 health: Optional[Health] = None) -> None:
        """Open the file, write header, metadata and attachments, and start the writer thread.

        :param path: output file (``.mcap``); overwritten if it exists.
        :param compression: chunk compression: ``'lz4'`` (default), ``'zstd'`` or ``'none'``.
        :param chunk_size: uncompressed size that closes a chunk [bytes].
        :param flush_period: longest wall time between chunk flushes [s]; None: no timed flush.
        :param flush_sim_period_ns: longest simulation time between flushes [ns]; None: off.
        :param queue_size: bound of the queue to the writer thread [messages].
        :param topics: topic selection; None records every topic added.
        :param decimation: record every k-th message of a topic, by topic name.
        :param cell_yaml: cell description text, attached as ``cell.yaml``.
        :param seed: seed of the run.
        :param step_ns: simulation step [ns] (to map command log times back to steps).
        :param metadata: further key/value pairs of the ``conveyor_twin`` metadata record.
        :param on_thread_start: called first in the writer thread (e.g. to raise its scheduling
            priority, so that a busy machine cannot delay the timed flush).
        :param health: where a failure of the writer is reported at once, with its traceback,
            as :data:`WRITER_NAME` (the twin's health); None: a health of the recorder's own,
            which prints the report. :meth:`close` raises it too.
        :raises RecordingError: if the file cannot be created or an option is invalid.
        """
        try:
            chosen = Compression('none' if compression == '' else compression)
        except ValueError:
            raise RecordingError(f'unknown compression {compression!r}: expected lz4, zstd '
                                 'or none') from None
        if chunk_size <= 0 or queue_size <= 0:
            raise RecordingError(f'chunk_size ({chunk_size}) and queue_size ({queue_size}) '
                                 'must be positive')
        if flush_period is not None and flush_period <= 0:
            raise RecordingError(f'flush_period must be positive, not {flush_period}')
        self.path = os.fspath(path)
        self.compression = chosen
        self._flush_period = flush_period
        self._flush_sim = flush_sim_period_ns
        self._flush_spacing = flush_period * WRITER_FLUSH_SHARE if flush_period else 0.0
        # record() flushes itself past this age of the last flush [s] (inf: never)
        self._force_age = flush_period * FORCED_FLUSH_SHARE if flush_period else float('inf')
        # monotonic time [s] at which the last flush began: everything queued before it is in
        # the file stream
        self._flushed_mark = time.monotonic()
        # one drainer at a time: the writer thread or a producer flushing itself
        self._io = threading.Lock()
        self._queue_size = queue_size
        self._selection = None if topics is None else frozenset(topics)
        self._decimation = dict(decimation or {})
        for name, k in self._decimation.items():
            if int(k) != k or k < 1:
                raise RecordingError(f'decimation of {name} must be an integer >= 1, not {k}')
        self._topics: Dict[str, _Topic] = {}
        self._queue: Deque[Tuple[int, Any, Any]] = deque()
        self._wake = threading.Event()
        self._closing = False
        self._closed = False
        self._error: Optional[BaseException] = None
        self._schema_ids: Dict[str, int] = {}
        self._sim_mark: Optional[int] = None
        self._by_index: List[_Topic] = []
        self.stats = RecorderStats(self.path)
        self._on_thread_start = on_thread_start
        self.health = health if health is not None else Health()
        self._info = {'version': __version__, 'library': LIBRARY,
                      'seed': '' if seed is None else str(int(seed)),
                      'step_ns': '' if step_ns is None else str(int(step_ns)),
                      'cell_name': _cell_name(cell_yaml),
                      'accepted_belt_commands': ACCEPTED_BELT_COMMANDS,
                      'accepted_actuator_commands': ACCEPTED_ACTUATOR_COMMANDS,
                      'created_unix_ns': str(time.time_ns())}
        self._info.update({str(k): str(v) for k, v in (metadata or {}).items()})
        try:
            self._stream = open(self.path, 'wb')
        except OSError as err:
            raise RecordingError(f'cannot create recording {self.path}: {err}') from None
        try:  # the header, metadata and cell: a full disk shows here, before any step
            self._file = McapFile(self._stream, profile='ros2', library=LIBRARY,
                                  compression=chosen.chunk_name, chunk_size=chunk_size)
            self._file.add_metadata('conveyor_twin', self._info)
            if cell_yaml is not None:
                self._file.add_attachment('cell.yaml', 'application/yaml', cell_yaml.encode())
            self._stream.flush()
        except OSError as err:
            try:
                self._stream.close()
            except OSError:
                pass  # closing flushes the same bytes again; the error below says why
            raise RecordingError(f'cannot write recording {self.path}: {err}') from None
        self.add_topic(ACCEPTED_BELT_COMMANDS, 'conveyor_twin_msgs/msg/BeltCommand',
                       essential=True)
        self.add_topic(ACCEPTED_ACTUATOR_COMMANDS, 'conveyor_twin_msgs/msg/ActuatorCommand',
                       essential=True)
        self._thread = threading.Thread(target=self._run, name='mcap-recorder', daemon=True)
        self._thread.start()

    # -- producer side (simulation thread) ------------------------------------------------------
    def add_topic(self, topic: str, type_name: str, *,
                  qos: Optional[qos_mod.OfferedQos] = None, decimation: Optional[int] = None,
                  essential: bool = False) -> bool:
        """Declare a topic before recording on it.

        :param topic: topic name as recorded (e.g. ``/parts``).
        :param type_name: full type name, e.g. ``conveyor_twin_msgs/msg/PartStates``; must be
            one of :data:`conveyor_twin.wire.schemas.SCHEMAS`.
        :param qos: offered QoS to store; default by type (:func:`qos.default_qos`).
        :param decimation: record every k-th message (overrides the constructor's mapping).
        :param essential: never decimate or drop (accepted commands).
        :return: True if the topic is selected for recording.
        :raises RecordingError: for an unknown type, a topic declared twice with another type,
            or a closed recorder.
        """
        if self._closing:
            raise RecordingError(f'{self.path}: recorder is closed')
        if type_name not in SCHEMAS:
            raise RecordingError(f'no ros2msg schema for type {type_name!r} (topic {topic})')
        known = self._topics.get(topic)
        if known is not None:
            if known.type_name != type_name:
                raise RecordingError(f'topic {topic} declared as {known.type_name} and '
                                     f'{type_name}')
            return known.selected
        k = 1 if essential else int(decimation or self._decimation.get(topic, 1))
        if k < 1:
            raise RecordingError(f'decimation of {topic} must be >= 1, not {k}')
        selected = essential or self._selection is None or topic in self._selection
        t = _Topic(len(self._by_index), topic, type_name, qos or qos_mod.default_qos(type_name),
                   k, essential, selected)
        self._topics[topic] = t
        self._by_index.append(t)
        self.stats.topics[topic] = t.stats
        if selected:
            self._queue.append((_REGISTER, t, None))
        return selected

    def record(self, topic: str, log_time_ns: int, data: bytes) -> bool:
        """Queue one message; never blocks.

        :param topic: a topic declared with :meth:`add_topic`.
        :param log_time_ns: simulation time of the message [ns].
        :param data: CDR bytes (with encapsulation header); must not be mutated afterwards.
        :return: True if queued; False if not selected, decimated or dropped (queue full).
        :raises RecordingError: for an undeclared topic.
        """
        t = self._topics.get(topic)
        if t is None:
            raise RecordingError(f'{self.path}: topic {topic} was not declared (add_topic)')
        if not t.selected:
            return False
        stats = t.stats
        stats.offered += 1
        if t.decimation != 1 and (stats.offered - 1) % t.decimation:
            stats.decimated += 1
            return False
        if len(self._queue) >= self._queue_size and not t.essential:
            stats.dropped += 1
            return False
        self._queue.append((t.index, log_time_ns, data, stats.offered))
        if time.monotonic() - self._flushed_mark >= self._force_age:
            self._flush_behind()
        return True

    def _flush_behind(self) -> None:
        """Drain and flush from the producer's thread: the writer thread is behind.

        Waits for a drain of the writer thread in progress; does nothing once the recorder
        failed or is closing (an error is reported to :attr:`health` at once and raised by
        :meth:`close`).
        """
        if self._error is not None or self._closing:
            return
        with self._io:
            if self._error is not None or \
                    time.monotonic() - self._flushed_mark < self._force_age:
                return  # the writer thread flushed meanwhile
            try:
                self._flush_queued()
                self.stats.forced_flushes += 1
            except BaseException as err:  # noqa: BLE001 - reported now, raised by close()
                self._fail(err)

    def record_accepted_command(self, kind: str, effective_time_ns: int, data: bytes) -> None:
        """Record an accepted command (never dropped).

        :param kind: ``'belt'``, ``'actuator'``, ``'spawn'`` (a ``spawn_parts`` call) or
            ``'reset'``.
        :param effective_time_ns: simulation time of the step at which it took effect [ns].
        :param data: the BeltCommand/ActuatorCommand CDR bytes.
        """
        topic = {'belt': ACCEPTED_BELT_COMMANDS, 'actuator': ACCEPTED_ACTUATOR_COMMANDS,
                 'spawn': ACCEPTED_SPAWNS, 'reset': ACCEPTED_RESETS}[kind]
        if topic not in self._topics:  # service calls: a channel only in runs that made them
            self.add_topic(topic, _CALL_TYPES[topic], essential=True)
        self.record(topic, effective_time_ns, data)

    def queued(self) -> int:
        """Return the number of messages waiting for the writer thread."""
        return len(self._queue)

    # -- writer thread ------------------------------------------------------------------------
    def _register(self, t: _Topic) -> None:
        schema_id = self._schema_ids.get(t.type_name)
        if schema_id is None:
            schema_id = self._file.add_schema(t.type_name, SchemaEncoding.ROS2,
                                              SCHEMAS[t.type_name].encode())
            self._schema_ids[t.type_name] = schema_id
        metadata = {'offered_qos_profiles': qos_mod.profiles_yaml([t.qos]),
                    'topic_type_hash': type_hash(t.type_name)}
        t.channel_id = self._file.add_channel(t.name, MessageEncoding.CDR, schema_id, metadata)

    def _drain(self) -> None:
        """Write the items queued when called (not those queued meanwhile, so a drain ends
        however fast the producer is); close a chunk whenever simulation time crossed a
        period. Call with ``_io`` held."""
        queue, by_index, add = self._queue, self._by_index, self._file.add_message
        sim_period = self._flush_sim
        for _ in range(len(queue)):
            item = queue.popleft()
            index = item[0]
            if index == _REGISTER:
                self._register(item[1])
                continue
            t = by_index[index]
            log_time = item[1]
            if sim_period is not None:
                if self._sim_mark is None:
                    self._sim_mark = log_time
                elif log_time - self._sim_mark >= sim_period:
                    self._file.flush()
                    self._sim_mark = log_time
            add(t.channel_id, item[3], log_time, log_time, item[2])
            t.stats.recorded += 1

    def _run(self) -> None:
        if self._on_thread_start is not None:
            try:
                self._on_thread_start()
            except Exception:  # noqa: BLE001 - a refused priority changes no data
                pass
        spacing = self._flush_spacing if self._flush_period else float('inf')
        try:
            while True:
                closing = self._closing
                with self._io:
                    if self._error is not None:
                        break
                    if time.monotonic() - self._flushed_mark >= spacing:
                        self._flush_queued()
                    else:
                        self._drain()
                    wait = max(0.0, self._flushed_mark + spacing - time.monotonic())
                if closing and not self._queue:
                    break
                self._wake.wait(min(POLL_PERIOD, wait))
        except BaseException as err:  # noqa: BLE001 - reported now, raised by close()
            self._fail(err)

    def _flush_queued(self) -> None:
        """Write everything queued now and close the chunk; call with ``_io`` held."""
        mark = time.monotonic()
        self._drain()
        self._file.flush()
        self._flushed_mark = mark

    def _fail(self, err: BaseException) -> None:
        """Report the writer's error to :attr:`health` (once, with its traceback), keep it for
        :meth:`close` and stop queueing work for it."""
        self._error = err
        self.stats.error = f'{type(err).__name__}: {err}'
        self._queue.clear()
        self.health.report(WRITER_NAME, err)

    # -- closing ------------------------------------------------------------------------------
    def close(self) -> RecorderStats:
        """Write what is queued, the summary and the final metadata; stop the thread.

        :return: the counters per topic.
        :raises RecordingError: if the writer thread failed.
        """
        if self._closed:
            return self.stats
        self._closing = True
        self._wake.set()
        self._thread.join()
        self._closed = True
        try:
            if self._error is None:
                self._file.add_metadata('conveyor_twin_recorder',
                                        {'stats': json.dumps(self.stats.as_dict())})
                self._file.add_metadata('rosbag2', {'serialized_metadata':
                                                    self._bag_metadata()})
                self._file.finish()
        except Exception as err:  # noqa: BLE001
            self._error = err
            self.health.report(WRITER_NAME, err)
        finally:
            self._stream.close()
        if self._error is not None:
            raise RecordingError(f'recording {self.path} failed: {self._error}') from \
                self._error
        return self.stats

    def _bag_metadata(self) -> str:
        start, end = self._file.time_range()
        counts = self._file.channel_counts()
        topics = [t for t in self._by_index if t.selected]
        return bag_metadata_yaml(
            os.path.basename(self.path), start, end, self._file.message_count,
            [(t.name, t.type_name, t.qos, counts.get(t.channel_id, 0)) for t in topics],
            {f'conveyor_twin.{k}': v for k, v in self._info.items() if v})

    def __enter__(self) -> 'McapRecorder':
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def bag_metadata_yaml(file_name: str, start_ns: int, end_ns: int, message_count: int,
                      topics: List[Tuple[str, str, qos_mod.OfferedQos, int]],
                      custom_data: Dict[str, str]) -> str:
    """Return rosbag2's ``serialized_metadata`` (BagMetadata YAML, version 9).

    :param topics: (name, type, offered qos, message count) per topic.
    """
    import yaml
    duration = end_ns - start_ns if message_count else 0
    node = {
        'version': ROSBAG2_METADATA_VERSION,
        'storage_identifier': 'mcap',
        'duration': {'nanoseconds': duration},
        'starting_time': {'nanoseconds_since_epoch': start_ns},
        'message_count': message_count,
        'topics_with_message_count': [
            {'topic_metadata': {'name': name, 'type': type_name, 'serialization_format': 'cdr',
                                'offered_qos_profiles': [qos_mod.profile_dict(q)],
                                'type_description_hash': _hash_or_empty(type_name)},
             'message_count': count}
            for name, type_name, q, count in topics],
        'compression_format': '',
        'compression_mode': '',
        'relative_file_paths': [file_name],
        'files': [{'path': file_name, 'starting_time': {'nanoseconds_since_epoch': start_ns},
                   'duration': {'nanoseconds': duration}, 'message_count': message_count}],
        'custom_data': custom_data,
        'ros_distro': ROS_DISTRO,
    }
    return yaml.safe_dump(node, sort_keys=False)


def _hash_or_empty(type_name: str) -> str:
    try:
        return type_hash(type_name)
    except KeyError:
        return ''


def _cell_name(cell_yaml: Optional[str]) -> str:
    """Return ``cell.name`` of a cell description text ('' if absent or unparsable)."""
    if not cell_yaml:
        return ''
    import yaml
    try:
        data = yaml.safe_load(cell_yaml)
        return str(data['cell']['name'])
    except Exception:  # noqa: BLE001 - the name is informative only
        return ''
