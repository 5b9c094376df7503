"""Read, summarize and recover MCAP recordings.

- :func:`read_messages` reads a closed recording through its index (``mcap``'s seeking
  reader, log-time order), or with ``linear=True`` scans the data section in file order
  (``log_time_order=False``), skipping damaged chunks: the way to read a killed recording.
- :func:`info` summarizes a recording like ``ros2 bag info``.
- :func:`recover` rewrites the intact part of a killed, truncated or damaged recording into a
  valid, indexed file and reports what it kept.

Damaged files give a :class:`RecordingError` naming the file and the problem, or a report of a
partial recovery; the scan is bounded by the file size, so it never hangs.
"""

from dataclasses import dataclass, field
import json
import os
import struct
from typing import Any, Dict, Iterable, Iterator, List, NamedTuple, Optional

from mcap.reader import make_reader

from . import scan
from ._mcapfile import MAGIC, McapFile
from .errors import RecordingError
from .qos import STREAM_QOS
from .writer import bag_metadata_yaml, LIBRARY

_FOOTER_SIZE = 9 + 20 + len(MAGIC)


class RecordedMessage(NamedTuple):
    """One message of a recording; times [ns] (simulation time for the twin's recordings)."""

    topic: str
    type_name: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes


def is_complete(path: str) -> bool:
    """Return True if the file ends with a valid MCAP footer and closing magic.

    :raises RecordingError: if the file cannot be read.
    """
    try:
        with open(path, 'rb') as f:
            size = f.seek(0, 2)
            if size < 8 + _FOOTER_SIZE:
                return False
            f.seek(0)
            if f.read(8) != MAGIC:
                return False
            f.seek(size - _FOOTER_SIZE)
            tail = f.read(_FOOTER_SIZE)
    except OSError as err:
        raise RecordingError(f'cannot read {path}: {err}') from None
    opcode, length, summary_start, _, _ = struct.unpack_from('<BQQQI', tail)
    return (tail[-8:] == MAGIC and opcode == 0x02 and length == 20
            and summary_start <= size - _FOOTER_SIZE)


def read_messages(path: str, *, topics: Optional[Iterable[str]] = None,
                  linear: bool = False) -> Iterator[RecordedMessage]:
    """Yield the messages of a recording.

    :param path: MCAP file.
    :param topics: only these topics; None: all.
    :param linear: scan in file order, skipping damaged chunks and stopping at the end of the
        intact data (for killed or damaged recordings); otherwise read through the index in
        log-time order, which needs a closed, intact file.
    :raises RecordingError: if the file is not closed or is damaged (indexed mode), or is not
        an MCAP file.
    """
    wanted = None if topics is None else frozenset(topics)
    if linear:
        yield from _read_linear(path, wanted)
        return
    if not is_complete(path):
        raise RecordingError(f'{path} has no valid footer (recording killed or truncated?): '
                             'read it with linear=True or rebuild it with recover()')
    try:
        with open(path, 'rb') as f:
            reader = make_reader(f, validate_crcs=True)
            for schema, channel, message in reader.iter_messages(
                    topics=None if wanted is None else list(wanted), log_time_order=True):
                yield RecordedMessage(channel.topic, schema.name if schema else '',
                                      message.log_time, message.publish_time, message.sequence,
                                      message.data)
    except RecordingError:
        raise
    except Exception as err:  # noqa: BLE001 - mcap, lz4, zstd and struct errors alike
        raise RecordingError(f'{path} is damaged: {type(err).__name__}: {err}; try '
                             'recover()') from None


def _read_linear(path: str, wanted: Optional[frozenset]) -> Iterator[RecordedMessage]:
    report = scan.ScanReport(path, 0)
    for m in scan.iter_scan(path, report):
        channel = report.channels.get(m.channel_id)
        if channel is None or (wanted is not None and channel.topic not in wanted):
            continue
        schema = report.schemas.get(channel.schema_id)
        yield RecordedMessage(channel.topic, schema.name if schema else '', m.log_time,
                              m.publish_time, m.sequence, m.data)


def read_metadata(path: str) -> Dict[str, Dict[str, str]]:
    """Return the metadata records of a recording by name (the last record of a name wins).

    Works on damaged files too (linear scan).

    :raises RecordingError: if the file cannot be read or is not MCAP.
    """
    return {name: data for name, data in scan.scan(path).metadata}


def read_attachment(path: str, name: str) -> bytes:
    """Return the data of an attachment, e.g. ``cell.yaml``.

    :raises RecordingError: if there is no such attachment or the file cannot be read.
    """
    for attachment_name, _, data in scan.scan(path).attachments:
        if attachment_name == name:
            return data
    raise RecordingError(f'{path} has no attachment {name!r}')


def info(path: str) -> Dict[str, Any]:
    """Summarize a recording like ``ros2 bag info``.

    Complete files are summarized from their summary section; others from a linear scan of
    their intact data (``complete`` False).

    :return: dict with ``path``, ``size``, ``complete``, ``profile``, ``library``,
        ``compression`` (sorted chunk compressions), ``chunk_count``, ``message_count``,
        ``start_ns``, ``end_ns``, ``duration_ns``, ``topics`` (name -> type, count,
        rate_hz, offered_qos_profiles, type_hash), ``cell_name``, ``seed``, ``step_ns``,
        ``version``, ``attachments``, ``recorder`` (counters of the recorder, if closed),
        ``damaged`` (chunks skipped) and ``stop_reason``.
    :raises RecordingError: if the file cannot be read or is not MCAP.
    """
    counts: Dict[int, int] = {}
    first: Dict[int, int] = {}
    last: Dict[int, int] = {}

    def count(m: scan.ScanMessage) -> None:
        counts[m.channel_id] = counts.get(m.channel_id, 0) + 1
        first.setdefault(m.channel_id, m.log_time)
        last[m.channel_id] = max(last.get(m.channel_id, m.log_time), m.log_time)

    report = scan.scan(path, count)
    topics = {}
    for cid, ch in sorted(report.channels.items()):
        n = counts.get(cid, 0)
        span = (last[cid] - first[cid]) if n > 1 else 0
        schema = report.schemas.get(ch.schema_id)
        topics[ch.topic] = {
            'type': schema.name if schema else '', 'count': n,
            'rate_hz': (n - 1) * 1e9 / span if span else 0.0,
            'offered_qos_profiles': ch.metadata.get('offered_qos_profiles', ''),
            'type_hash': ch.metadata.get('topic_type_hash', '')}
    start = min(first.values()) if first else 0
    end = max(last.values()) if last else 0
    meta = {name: data for name, data in report.metadata}
    twin = meta.get('conveyor_twin', {})
    recorder = meta.get('conveyor_twin_recorder', {}).get('stats')
    return {
        'path': path, 'size': report.size, 'complete': report.complete,
        'profile': report.profile, 'library': report.library,
        'compression': sorted(report.compressions), 'chunk_count': report.chunks,
        'message_count': sum(counts.values()), 'start_ns': start, 'end_ns': end,
        'duration_ns': end - start, 'topics': topics,
        'cell_name': twin.get('cell_name', ''),
        'seed': int(twin['seed']) if twin.get('seed') else None,
        'step_ns': int(twin['step_ns']) if twin.get('step_ns') else None,
        'version': twin.get('version', ''),
        'attachments': [name for name, _, _ in report.attachments],
        'recorder': json.loads(recorder) if recorder else None,
        'damaged': [f'byte {offset}: {why}' for offset, why in report.damaged],
        'stop_reason': report.stop_reason,
    }


@dataclass
class RecoveryReport:
    """What :func:`recover` kept; times [ns]."""

    source: str
    destination: str
    complete_source: bool
    messages: Dict[str, int] = field(default_factory=dict)
    last_log_time: Dict[str, int] = field(default_factory=dict)
    orphaned: int = 0
    damaged: List[str] = field(default_factory=list)
    stop_reason: str = ''

    @property
    def total(self) -> int:
        """Messages recovered in all topics."""
        return sum(self.messages.values())

    @property
    def last_time(self) -> Optional[int]:
        """Log time of the last recovered message (None if none)."""
        return max(self.last_log_time.values()) if self.last_log_time else None


def recover(src: str, dst: str, *, compression: str = 'lz4') -> RecoveryReport:
    """Rebuild a valid, indexed recording from the intact data of a killed or damaged one.

    Schemas, channels, metadata, attachments and every message of the intact chunks are copied
    in file order; damaged chunks are skipped and listed. The result carries a fresh summary,
    a ``rosbag2`` metadata record and a ``conveyor_twin_recovery`` metadata record.

    :param src: the damaged recording.
    :param dst: the file to write (must differ from ``src``).
    :param compression: chunk compression of the new file (``lz4``, ``zstd``, ``none``).
    :raises RecordingError: if ``src`` cannot be read or is not MCAP at all, or ``dst``
        cannot be written.
    """
    if os.path.abspath(src) == os.path.abspath(dst):
        raise RecordingError(f'recover would overwrite its source {src}')
    report = scan.ScanReport(src, 0)
    result = RecoveryReport(src, dst, False)
    channel_map: Dict[int, int] = {}
    schema_map: Dict[int, int] = {}
    topics: Dict[int, Any] = {}
    comp = {'none': ''}.get(compression, compression)
    try:
        stream = open(dst, 'wb')
    except OSError as err:
        raise RecordingError(f'cannot create {dst}: {err}') from None
    with stream:
        out = McapFile(stream, profile='ros2', library=LIBRARY, compression=comp,
                       chunk_size=768 * 1024)
        for m in scan.iter_scan(src, report):
            cid = channel_map.get(m.channel_id)
            if cid is None:
                channel = report.channels.get(m.channel_id)
                if channel is None:
                    result.orphaned += 1
                    continue
                schema = report.schemas.get(channel.schema_id)
                if schema is not None and schema.id not in schema_map:
                    schema_map[schema.id] = out.add_schema(schema.name, schema.encoding,
                                                           schema.data)
                cid = out.add_channel(channel.topic, channel.message_encoding,
                                      schema_map.get(channel.schema_id, 0), channel.metadata)
                channel_map[m.channel_id] = cid
                topics[cid] = (channel.topic, schema.name if schema else '')
            out.add_message(cid, m.sequence, m.log_time, m.publish_time, m.data)
            topic = topics[cid][0]
            result.messages[topic] = result.messages.get(topic, 0) + 1
            result.last_log_time[topic] = max(result.last_log_time.get(topic, 0), m.log_time)
        # channels without surviving messages are kept too (topic list stays complete)
        for old_id, channel in sorted(report.channels.items()):
            if old_id not in channel_map:
                schema = report.schemas.get(channel.schema_id)
                if schema is not None and schema.id not in schema_map:
                    schema_map[schema.id] = out.add_schema(schema.name, schema.encoding,
                                                           schema.data)
                cid = out.add_channel(channel.topic, channel.message_encoding,
                                      schema_map.get(channel.schema_id, 0), channel.metadata)
                channel_map[old_id] = cid
                topics[cid] = (channel.topic, schema.name if schema else '')
        result.complete_source = report.complete
        result.damaged = [f'byte {offset}: {why}' for offset, why in report.damaged]
        result.stop_reason = report.stop_reason
        for name, data in report.metadata:
            if name != 'rosbag2':
                out.add_metadata(name, data)
        for name, media_type, data in report.attachments:
            out.add_attachment(name, media_type, data)
        out.add_metadata('conveyor_twin_recovery', {
            'source': os.path.basename(src), 'stop_reason': result.stop_reason,
            'damaged': json.dumps(result.damaged), 'orphaned': str(result.orphaned),
            'messages': json.dumps(result.messages)})
        start, end = out.time_range()
        counts = out.channel_counts()
        custom = {f'conveyor_twin.{k}': v
                  for k, v in dict(report.metadata).get('conveyor_twin', {}).items() if v}
        out.add_metadata('rosbag2', {'serialized_metadata': bag_metadata_yaml(
            os.path.basename(dst), start, end, out.message_count,
            [(topic, type_name, STREAM_QOS, counts.get(cid, 0))
             for cid, (topic, type_name) in sorted(topics.items()) if type_name],
            custom)})
        out.finish()
    return result
