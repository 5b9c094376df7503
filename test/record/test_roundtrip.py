"""Write with McapRecorder, read back with independent readers and compare every field."""

import json

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest
import yaml

from conveyor_twin.record import reader
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.wire import cdr
from conveyor_twin.wire.typehash import type_hash
from .helpers import CELL_YAML, DT_NS, record_run, TOPICS

COMPRESSIONS = ['lz4', 'zstd', 'none']


def stamp_ns(header):
    return header.stamp.sec * 10**9 + header.stamp.nanosec


def check_decoded(topic, msg, log_time, expected):
    """Compare a message decoded by mcap_ros2 or rosbags with what was encoded."""
    if topic == '/parts':
        assert stamp_ns(msg.header) == log_time and msg.step == log_time // DT_NS
        for name, array in zip(('id', 'part_type', 'x', 'y', 'yaw', 'vx', 'vy', 'wz'), expected):
            assert np.array_equal(np.asarray(getattr(msg, name)), array), name
    elif topic == '/density':
        assert msg.zone == 'buffer' and (msg.nx, msg.ny) == (3, 2)
        assert np.array_equal(np.asarray(msg.density, np.float32), expected.ravel())
    elif topic == '/light_barriers':
        assert list(msg.name) == ['lb_in', 'lb_out']
        assert list(msg.blocked) == expected[0].tolist()
        assert list(msg.edge_count) == expected[1].tolist()
    elif topic in ('/belt_states', '/actuator_states'):
        actual = msg.speed if topic == '/belt_states' else msg.position
        assert list(actual) == expected[1].tolist()
    elif topic == '/light_barrier_edges':
        assert msg.part_id == expected and stamp_ns(msg.header) == log_time - 300
    elif topic == '/clock':
        assert msg.clock.sec * 10**9 + msg.clock.nanosec == expected == log_time
    elif topic.endswith('belt_command'):
        assert (msg.belt, msg.speed) == expected
    elif topic.endswith('actuator_command'):
        assert (msg.actuator, msg.position) == expected
    else:
        raise AssertionError(topic)


@pytest.mark.smoke
@pytest.mark.parametrize('compression', COMPRESSIONS)
def test_roundtrip_mcap_reader(tmp_path, compression):
    path = tmp_path / 'run.mcap'
    stats, sent = record_run(path, compression=compression, chunk_size=8192)
    assert stats.dropped == 0
    with open(path, 'rb') as f:
        mcap = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        header = mcap.get_header()
        assert header.profile == 'ros2'
        summary = mcap.get_summary()
        assert summary.statistics.message_count == sum(len(v) for v in sent.values())
        assert summary.statistics.chunk_count > 1
        assert {c.compression for c in summary.chunk_indexes} == \
            {compression if compression != 'none' else ''}
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert schema.encoding == 'ros2msg' and channel.message_encoding == 'cdr'
            assert channel.metadata['topic_type_hash'] == type_hash(schema.name)
            qos = yaml.safe_load(channel.metadata['offered_qos_profiles'])
            assert qos[0]['reliability'] in ('reliable', 'best_effort')
            assert qos[0]['deadline'] == {'sec': 9223372036, 'nsec': 854775807}
        got = {topic: [] for topic in sent}
        for schema, channel, message, decoded in mcap.iter_decoded_messages(
                log_time_order=False):
            assert message.publish_time == message.log_time
            got[channel.topic].append((message.log_time, message.data, decoded,
                                       message.sequence))
        metadata = {m.name: m.metadata for m in mcap.iter_metadata()}
        attachments = {a.name: a.data for a in mcap.iter_attachments()}
    for topic, items in sent.items():
        assert len(got[topic]) == len(items), topic
        for (t, data, expected), (log_time, raw, decoded, seq) in zip(items, got[topic]):
            assert (log_time, raw) == (t, data)
            check_decoded(topic, decoded, t, expected)
        assert [g[3] for g in got[topic]] == list(range(1, len(items) + 1))
    assert attachments['cell.yaml'].decode() == CELL_YAML
    assert metadata['conveyor_twin']['seed'] == '7'
    assert metadata['conveyor_twin']['step_ns'] == str(DT_NS)
    assert metadata['conveyor_twin']['cell_name'] == 'test_rig'
    bag = yaml.safe_load(metadata['rosbag2']['serialized_metadata'])
    assert bag['version'] == 9 and bag['storage_identifier'] == 'mcap'
    assert bag['message_count'] == sum(len(v) for v in sent.values())
    assert bag['ros_distro'] == 'kilted'
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in bag['topics_with_message_count']}
    assert counts == {topic: len(items) for topic, items in sent.items()}
    recorder = json.loads(metadata['conveyor_twin_recorder']['stats'])
    assert recorder['topics']['/parts']['recorded'] == len(sent['/parts'])


@pytest.mark.smoke
@pytest.mark.parametrize('compression', COMPRESSIONS)
def test_roundtrip_rosbags(tmp_path, compression):
    rosbag2 = pytest.importorskip('rosbags.rosbag2')
    typesys = pytest.importorskip('rosbags.typesys')
    path = tmp_path / 'run.mcap'
    _, sent = record_run(path, compression=compression, chunk_size=8192)
    store = typesys.get_typestore(typesys.Stores.EMPTY)
    got = {topic: [] for topic in sent}
    with rosbag2.Reader(path) as bag:
        for connection in bag.connections:
            store.register(typesys.get_types_from_msg(connection.msgdef.data,
                                                      connection.msgtype))
        assert bag.message_count == sum(len(v) for v in sent.values())
        assert {c.topic: c.msgcount for c in bag.connections} == \
            {topic: len(items) for topic, items in sent.items()}
        qos = {c.topic: c.ext.offered_qos_profiles[0] for c in bag.connections}
        assert qos['/clock'].reliability.name == 'BEST_EFFORT' and qos['/clock'].depth == 1
        assert qos['/parts'].reliability.name == 'RELIABLE' and qos['/parts'].depth == 100
        for connection, timestamp, data in bag.messages():
            got[connection.topic].append(
                (timestamp, store.deserialize_cdr(data, connection.msgtype)))
    for topic, items in sent.items():
        assert sorted(g[0] for g in got[topic]) == [t for t, _, _ in items]
        for (t, _, expected), (timestamp, msg) in zip(items, got[topic]):
            check_decoded(topic, msg, t, expected)


def test_own_reader_indexed_and_linear_agree(tmp_path):
    path = tmp_path / 'run.mcap'
    _, sent = record_run(path, chunk_size=4096)
    indexed = list(reader.read_messages(path))
    linear = list(reader.read_messages(path, linear=True))
    assert sorted(indexed) == sorted(linear)
    assert [m.log_time for m in indexed] == sorted(m.log_time for m in indexed)
    parts = [m for m in indexed if m.topic == '/parts']
    assert [m.data for m in parts] == [d for _, d, _ in sent['/parts']]
    decoded = cdr.decode_part_states(parts[-1].data)
    assert decoded.stamp_ns == parts[-1].log_time
    only = list(reader.read_messages(path, topics=['/clock']))
    assert {m.topic for m in only} == {'/clock'} and len(only) == len(sent['/clock'])
    commands = [m for m in indexed if m.topic.endswith('belt_command')]
    assert [cdr.decode_belt_command(m.data) for m in commands] == [
        e for _, _, e in sent['/conveyor_twin/accepted/belt_command']]
    assert [m.log_time // DT_NS for m in commands] == [11, 31]


def test_info(tmp_path):
    path = tmp_path / 'run.mcap'
    _, sent = record_run(path, steps=101, compression='zstd')
    summary = reader.info(path)
    assert summary['complete'] and summary['compression'] == ['zstd']
    assert summary['cell_name'] == 'test_rig' and summary['seed'] == 7
    assert summary['step_ns'] == DT_NS and summary['attachments'] == ['cell.yaml']
    assert summary['duration_ns'] == 100 * DT_NS
    assert summary['message_count'] == sum(len(v) for v in sent.values())
    assert summary['topics']['/clock']['count'] == 101
    assert summary['topics']['/clock']['rate_hz'] == pytest.approx(1000.0)
    assert summary['topics']['/light_barrier_edges']['rate_hz'] == pytest.approx(200.0)
    assert summary['topics']['/parts']['type'] == TOPICS['/parts']
    assert summary['recorder']['topics']['/parts']['dropped'] == 0
    assert reader.read_metadata(path)['conveyor_twin']['version']
    assert reader.read_attachment(path, 'cell.yaml').decode() == CELL_YAML


def test_decimation_and_selection(tmp_path):
    path = tmp_path / 'run.mcap'
    stats, sent = record_run(path, steps=30, decimation={'/parts': 3, '/clock': 10},
                             topics=['/parts', '/clock', '/belt_states'])
    assert [t // DT_NS for t, _, _ in sent['/parts']] == list(range(0, 30, 3))
    assert [t // DT_NS for t, _, _ in sent['/clock']] == [0, 10, 20]
    assert stats.topics['/parts'].decimated == 20 and stats.topics['/parts'].recorded == 10
    assert stats.topics['/density'].offered == 0 and sent['/density'] == []
    summary = reader.info(path)
    assert set(summary['topics']) == {'/parts', '/clock', '/belt_states',
                                      '/conveyor_twin/accepted/belt_command',
                                      '/conveyor_twin/accepted/actuator_command'}
    seqs = [m.sequence for m in reader.read_messages(path, topics=['/parts'])]
    assert seqs == list(range(1, 30, 3))  # offered index: gaps show decimation
    # commands are essential: never decimated, always recorded
    assert summary['topics']['/conveyor_twin/accepted/belt_command']['count'] == 1
    assert summary['topics']['/conveyor_twin/accepted/actuator_command']['count'] == 1


def test_full_queue_drops_are_counted(tmp_path):
    path = tmp_path / 'run.mcap'
    rec = McapRecorder(path, queue_size=10, flush_period=None)
    rec.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
    gate = __import__('threading').Event()
    add = rec._file.add_message

    def blocked_add(*args):  # hold the writer thread until the producer is done
        gate.wait(10)
        add(*args)

    rec._file.add_message = blocked_add
    accepted = [rec.record('/clock', i * DT_NS, cdr.encode_clock(i * DT_NS))
                for i in range(100)]
    rec.record_accepted_command('belt', 5, cdr.encode_belt_command('main', 1.0))
    gate.set()
    stats = rec.close()
    clock = stats.topics['/clock']
    assert clock.offered == 100 and clock.dropped == 100 - sum(accepted) > 0
    assert clock.recorded == sum(accepted) <= 11
    assert stats.topics['/conveyor_twin/accepted/belt_command'].recorded == 1
    summary = reader.info(path)
    assert summary['topics']['/clock']['count'] == clock.recorded
    assert summary['recorder']['topics']['/clock']['dropped'] == clock.dropped


def wait_for(condition, timeout=10.0):
    import time
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.01)
    return condition()


@pytest.mark.parametrize('mode', ['wall', 'sim'])
def test_timed_flush_writes_chunks_before_close(tmp_path, mode):
    path = tmp_path / 'run.mcap'
    options = ({'flush_period': 0.05} if mode == 'wall'
               else {'flush_period': None, 'flush_sim_period_ns': 10 * DT_NS})
    rec = McapRecorder(path, chunk_size=64 << 20, **options)
    rec.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
    for i in range(30):
        rec.record('/clock', i * DT_NS, cdr.encode_clock(i * DT_NS))

    def flushed_steps():
        return [m.log_time // DT_NS for m in reader.read_messages(path, linear=True)
                if m.topic == '/clock']

    try:
        if mode == 'wall':
            assert wait_for(lambda: len(flushed_steps()) == 30)
        else:  # flushed once sim time advanced by 10 steps past the previous flush
            assert wait_for(lambda: len(flushed_steps()) >= 20)
            assert len(flushed_steps()) < 30
    finally:
        rec.close()
    assert len(flushed_steps()) == 30


def test_recorder_errors(tmp_path):
    with pytest.raises(RecordingError, match='cannot create'):
        McapRecorder(tmp_path / 'missing' / 'x.mcap')
    with pytest.raises(RecordingError, match='compression'):
        McapRecorder(tmp_path / 'x.mcap', compression='gzip')
    with pytest.raises(RecordingError, match='decimation'):
        McapRecorder(tmp_path / 'x.mcap', decimation={'/parts': 0})
    with McapRecorder(tmp_path / 'x.mcap') as rec:
        with pytest.raises(RecordingError, match='not declared'):
            rec.record('/nope', 0, b'')
        with pytest.raises(RecordingError, match='no ros2msg schema'):
            rec.add_topic('/x', 'foo_msgs/msg/Bar')
        rec.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
        with pytest.raises(RecordingError, match='declared as'):
            rec.add_topic('/clock', 'conveyor_twin_msgs/msg/PartStates')
    with pytest.raises(RecordingError, match='closed'):
        rec.add_topic('/y', 'rosgraph_msgs/msg/Clock')
    assert reader.info(tmp_path / 'x.mcap')['complete']


class _Asleep:
    """Stands in for the writer thread's wake-up event: the thread sleeps until close."""

    def __init__(self):
        import threading
        self._event = threading.Event()

    def wait(self, timeout=None):
        return self._event.wait(30.0)

    def set(self):
        self._event.set()


def test_record_flushes_itself_when_the_writer_thread_is_behind(tmp_path):
    import time
    path = tmp_path / 'run.mcap'
    flush_period = 0.05
    rec = McapRecorder(path, chunk_size=64 << 20, flush_period=flush_period)
    rec.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
    rec._wake = _Asleep()  # the writer thread never runs again before close
    recorded_at = []
    try:
        step = 0
        while not recorded_at or recorded_at[-1] - recorded_at[0] < 6 * flush_period:
            rec.record('/clock', step * DT_NS, cdr.encode_clock(step * DT_NS))
            recorded_at.append(time.monotonic())
            step += 1
            time.sleep(0.001)
        in_file = [m.log_time // DT_NS for m in reader.read_messages(path, linear=True)
                   if m.topic == '/clock']
        # every message recorded more than a flush period before the last one is in the file
        older = sum(1 for t in recorded_at if t <= recorded_at[-1] - flush_period)
        assert older > 0 and in_file[:older] == list(range(older))
        assert rec.stats.forced_flushes >= 3
    finally:
        stats = rec.close()
    assert stats.topics['/clock'].recorded == step and stats.dropped == 0


def test_memory_per_chunk_stays_small(tmp_path):
    import tracemalloc
    rec = McapRecorder(tmp_path / 'run.mcap', flush_period=None, flush_sim_period_ns=DT_NS)
    for topic, type_name in (('/clock', 'rosgraph_msgs/msg/Clock'),
                             ('/parts', 'conveyor_twin_msgs/msg/PartStates')):
        rec.add_topic(topic, type_name)
    clock = cdr.encode_clock(0)
    chunks = 3000

    def record(first):
        for i in range(first, first + chunks):   # a chunk per step (sim-time flush)
            rec.record('/clock', i * DT_NS, clock)
            rec.record('/parts', i * DT_NS, clock)
        while rec.queued():
            __import__('time').sleep(0.01)

    record(0)
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    record(chunks)
    grown = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    rec.close()
    assert grown < chunks * 400, grown / chunks     # bytes kept per chunk until close
    assert reader.info(tmp_path / 'run.mcap')['topics']['/clock']['count'] == 2 * chunks
