"""The reference recordings of ``bags/`` (made with ``conveyor-twin run --record``).

Read with independent readers (mcap + mcap-ros2-support, rosbags, rclpy's typesupport), checked
for gaps in ``step``, summarized by ``info``, and re-simulated bit for bit; a copy with one
altered byte must fail naming the message.
"""

import dataclasses
import pathlib
import subprocess
import sys

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from mcap_ros2.decoder import DecoderFactory
import numpy as np
import pytest

from conveyor_twin.record import reader
from conveyor_twin.record.writer import ACCEPTED_ACTUATOR_COMMANDS, ACCEPTED_BELT_COMMANDS
from conveyor_twin.wire import cdr

ROOT = pathlib.Path(__file__).resolve().parents[2]
BAGS_DIR = ROOT / 'bags'
BAGS = sorted(p.name for p in BAGS_DIR.glob('*.mcap'))
DT_NS = 1_000_000
MAX_BAG_BYTES = 5 * 1024 * 1024
# s a resimulate command may take: it loads the kernels and reruns 4 s of the cell, minutes on a
# loaded 2-core machine (a hang still ends the test)
CLI_TIMEOUT = 900
EVERY_STEP = ('/parts', '/light_barriers', '/belt_states', '/actuator_states', '/clock')
STALE = ('{bag} no longer re-simulates with this software: if the change of behaviour is '
         'intended, regenerate the bags with bags/make_bags.sh (see bags/README.md). {what}')


def test_bags_exist_are_small_and_documented():
    assert set(BAGS) >= {'default_4s.mcap', 'default_markers_2s.mcap'}
    readme = (BAGS_DIR / 'README.md').read_text()
    script = (BAGS_DIR / 'make_bags.sh').read_text()
    for bag in BAGS:
        assert (BAGS_DIR / bag).stat().st_size <= MAX_BAG_BYTES, bag
        assert bag in readme and bag in script, bag


@pytest.mark.smoke
@pytest.mark.parametrize('bag', BAGS)
def test_info(bag):
    summary = reader.info(str(BAGS_DIR / bag))
    assert summary['complete'] and summary['cell_name'] == 'seed_test_rig'
    assert summary['step_ns'] == DT_NS and summary['attachments'] == ['cell.yaml']
    steps = summary['duration_ns'] // DT_NS + 1
    for topic in EVERY_STEP:
        assert summary['topics'][topic]['count'] == steps, topic
    meta = reader.read_metadata(str(BAGS_DIR / bag))['conveyor_twin']
    assert meta['recorded_by'] == 'conveyor-twin run' and meta['version']
    assert int(meta['seed']) in (1, 7) and meta['commands']


@pytest.mark.parametrize('bag', BAGS)
def test_streams_have_no_gap_in_step(bag):
    path = str(BAGS_DIR / bag)
    steps = {topic: [] for topic in EVERY_STEP}
    sequences = {}
    for m in reader.read_messages(path):
        sequences.setdefault(m.topic, []).append(m.sequence)
        if m.topic == '/parts':
            parts = cdr.decode_part_states(m.data)
            steps[m.topic].append(parts.step)
            assert parts.stamp_ns == m.log_time
        elif m.topic == '/light_barriers':
            steps[m.topic].append(cdr.decode_light_barrier_states(m.data)[2])
        elif m.topic in EVERY_STEP:
            steps[m.topic].append(m.log_time // DT_NS)
            assert m.log_time % DT_NS == 0
    n = len(steps['/clock'])
    assert n >= 2000
    for topic, values in steps.items():
        assert values == list(range(1, n + 1)), topic
    for topic, seq in sequences.items():  # nothing decimated or dropped
        assert seq == list(range(1, len(seq) + 1)), topic
    clock = [cdr.decode_clock(m.data) for m in reader.read_messages(path, topics=['/clock'])]
    assert clock == [k * DT_NS for k in range(1, n + 1)]


def plain(value):
    """Return a decoded message (mcap_ros2 or rosbags object) as nested plain data."""
    if isinstance(value, (int, float, str)):
        return value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.name != '__msgtype__' and not f.name.isupper()}
    slots = getattr(type(value), '__slots__', None)
    if slots and not isinstance(value, (str, bytes)):
        return {name: plain(getattr(value, name)) for name in slots}
    if isinstance(value, np.ndarray) and value.dtype != object:
        return value.tolist()
    if isinstance(value, (list, tuple, np.ndarray)):
        if len(value) and isinstance(value[0], (int, float, bool, str)):
            return list(value)
        return [plain(v) for v in value]
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, np.generic):
        return value.item()
    return value


# every message of the markers bag (every stream, markers, diagnostics, commands) by two readers,
# and of the other only the type the first lacks (its streams would add ~10 s on a loaded CI
# machine and only more of the same types): bag -> topics (None: all)
DECODED_BAGS = {'default_markers_2s.mcap': None, 'default_4s.mcap': ['/light_barrier_edges']}


@pytest.fixture(scope='module')
def decoded():
    """{bag: {(topic, sequence): (log time, mcap_ros2 plain, rosbags plain)}}."""
    from rosbags import rosbag2, typesys
    out = {}
    for bag, topics in DECODED_BAGS.items():
        path = BAGS_DIR / bag
        got = {}
        with open(path, 'rb') as f:
            mcap = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
            for _, channel, message, msg in mcap.iter_decoded_messages(
                    topics=topics, log_time_order=False):
                got[(channel.topic, message.sequence)] = [message.log_time, plain(msg), None]
        store = typesys.get_typestore(typesys.Stores.EMPTY)
        with rosbag2.Reader(path) as rb:
            for connection in rb.connections:
                store.register(typesys.get_types_from_msg(connection.msgdef.data,
                                                          connection.msgtype))
            seq = {}
            wanted = [c for c in rb.connections if topics is None or c.topic in topics]
            for connection, timestamp, data in rb.messages(connections=wanted):
                k = seq[connection.topic] = seq.get(connection.topic, 0) + 1
                item = got[(connection.topic, k)]
                assert item[0] == timestamp
                msg = store.deserialize_cdr(data, connection.msgtype)
                item[2] = plain(msg)
        out[bag] = got
    return out


@pytest.mark.parametrize('bag', sorted(DECODED_BAGS))
def test_independent_readers_decode_every_message_alike(bag, decoded):
    got = decoded[bag]
    counts = reader.info(str(BAGS_DIR / bag))['topics']
    wanted = DECODED_BAGS[bag] or list(counts)
    assert len(got) == sum(counts[t]['count'] for t in wanted) > 0
    for key, (_, by_mcap, by_rosbags) in got.items():
        assert by_rosbags is not None and by_mcap == by_rosbags, key
    topics = {topic for topic, _ in got}
    if DECODED_BAGS[bag] is None:
        assert {'/diagnostics', '/markers', ACCEPTED_BELT_COMMANDS,
                ACCEPTED_ACTUATOR_COMMANDS, *EVERY_STEP} <= topics
    for (topic, _), (log_time, msg, _) in got.items():
        if topic in ('/parts', '/light_barriers', '/belt_states', '/diagnostics'):
            stamp = msg['header']['stamp']
            assert stamp['sec'] * 10**9 + stamp['nanosec'] == log_time, topic
    if bag == 'default_markers_2s.mcap':
        markers = [msg for (topic, _), (_, msg, _) in got.items() if topic == '/markers']
        # 2 s at 30 Hz, recorded in realtime (the micro node builds markers off the stepping
        # thread and publishes only the latest due one, so a busy machine may skip a few)
        assert 45 <= len(markers) <= 60 and all(m['markers'] for m in markers)


@pytest.mark.smoke
@pytest.mark.ros
def test_markers_and_diagnostics_decode_with_ros_typesupport(decoded):
    """rclpy's own CDR decoder (the C typesupport) agrees with mcap_ros2 on every message."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message
    from visualization_msgs.msg import MarkerArray

    bag = 'default_markers_2s.mcap'
    types = {'/markers': MarkerArray, '/diagnostics': DiagnosticArray}
    counts = reader.info(str(BAGS_DIR / bag))['topics']
    seen = 0
    for m in reader.read_messages(str(BAGS_DIR / bag), topics=list(types)):
        msg = deserialize_message(m.data, types[m.topic])
        expected = decoded[bag][(m.topic, m.sequence)][1]
        if m.topic == '/markers':
            assert len(msg.markers) == len(expected['markers'])
            for a, b in zip(msg.markers, expected['markers']):
                assert (a.ns, a.id, a.type) == (b['ns'], b['id'], b['type'])
                assert [(p.x, p.y, p.z) for p in a.points] == \
                    [(p['x'], p['y'], p['z']) for p in b['points']]
                assert (a.color.r, a.color.a) == (b['color']['r'], b['color']['a'])
        else:
            assert [(kv.key, kv.value) for kv in msg.status[0].values] == \
                [(kv['key'], kv['value']) for kv in expected['status'][0]['values']]
        seen += 1
    assert seen == counts['/markers']['count'] + counts['/diagnostics']['count'] > 45


@pytest.mark.smoke
@pytest.mark.ros
@pytest.mark.parametrize('bag', BAGS)
def test_resimulate_bag_is_bit_identical(bag, ros_context):
    from conveyor_twin.record.resimulate import resimulate
    report = resimulate(str(BAGS_DIR / bag), context=ros_context)
    if not report.ok:
        pytest.fail(STALE.format(bag=bag, what=f'First difference: {report.difference}'))
    counts = reader.info(str(BAGS_DIR / bag))['topics']
    for topic in EVERY_STEP + ('/light_barrier_edges', '/markers'):
        if topic in counts:
            assert report.compared.get(topic, 0) == counts[topic]['count'], topic
    assert report.commands == 3 and report.skipped == {'/diagnostics': counts['/diagnostics']
                                                       ['count']}


def altered_copy(src, dst, topic, sequence):
    """Copy a recording record by record, flipping the lowest bit of one message's last byte.

    :return: the byte offset altered in that message.
    """
    with open(src, 'rb') as f, open(dst, 'wb') as out:
        r = make_reader(f)
        header, summary = r.get_header(), r.get_summary()
        w = Writer(out, compression=CompressionType.NONE)
        w.start(profile=header.profile, library=header.library)
        schemas = {sid: w.register_schema(s.name, s.encoding, s.data)
                   for sid, s in summary.schemas.items()}
        channels = {cid: w.register_channel(c.topic, c.message_encoding, schemas[c.schema_id],
                                            c.metadata)
                    for cid, c in summary.channels.items()}
        for a in r.iter_attachments():
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        for m in r.iter_metadata():
            w.add_metadata(m.name, m.metadata)
        offset = None
        for _, channel, message in r.iter_messages(log_time_order=False):
            data = message.data
            if channel.topic == topic and message.sequence == sequence:
                offset = len(data) - 1
                data = data[:offset] + bytes([data[offset] ^ 1])
            w.add_message(channels[channel.id], message.log_time, data, message.publish_time,
                          message.sequence)
        w.finish()
    assert offset is not None
    return offset


@pytest.mark.ros
def test_resimulate_detects_an_altered_message(tmp_path, ros_context):
    from conveyor_twin.record.resimulate import resimulate
    path = tmp_path / 'altered.mcap'
    offset = altered_copy(BAGS_DIR / 'default_4s.mcap', path, '/parts', 3210)
    report = resimulate(str(path), context=ros_context)
    d = report.difference
    assert d is not None
    assert (d.topic, d.sequence, d.step, d.byte_offset) == ('/parts', 3210, 3210, offset)
    assert d.field.startswith('wz[') and d.recorded != d.resimulated
    assert report.compared['/parts'] == 3209
    # and the command line says so with exit code 1
    result = subprocess.run([sys.executable, '-m', 'conveyor_twin.cli', 'resimulate',
                             str(path)], capture_output=True, text=True, timeout=CLI_TIMEOUT)
    assert result.returncode == 1, result.stdout + result.stderr
    assert 'FIRST DIFFERENCE: /parts message #3210 (step 3210' in result.stdout
    assert f'byte offset {offset}: field wz[' in result.stdout


def test_resimulate_refuses_what_it_cannot_rerun(tmp_path):
    foreign = tmp_path / 'foreign.mcap'
    with open(foreign, 'wb') as f:
        w = Writer(f)
        w.start(profile='ros2', library='test')
        w.finish()
    for path, why in ((foreign, 'no conveyor_twin metadata'),
                      (tmp_path / 'missing.mcap', 'no such file')):
        result = subprocess.run([sys.executable, '-m', 'conveyor_twin.cli', 'resimulate',
                                 str(path)], capture_output=True, text=True, timeout=CLI_TIMEOUT)
        assert result.returncode == 2 and why in result.stderr, result.stderr


@pytest.mark.ros
@pytest.mark.parametrize('fraction', [0.3, 0.77])
def test_resimulate_a_truncated_recording_compares_what_is_left(tmp_path, ros_context,
                                                                fraction):
    from conveyor_twin.record.resimulate import resimulate
    data = (BAGS_DIR / 'default_markers_2s.mcap').read_bytes()
    path = tmp_path / 'cut.mcap'
    path.write_bytes(data[:int(len(data) * fraction)])
    report = resimulate(str(path), context=ros_context)
    assert report.ok and not report.complete_source, str(report.difference)
    left = sum(1 for m in reader.read_messages(str(path), linear=True)
               if m.topic in EVERY_STEP)
    assert 0 < sum(report.compared[t] for t in EVERY_STEP) == left
