"""The standalone recorder: in-process round trip; ``conveyor-twin record`` stopped by SIGINT."""

import os
import signal
import subprocess
import sys
import time

import pytest
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy

from conveyor_twin.contract import Stamp, TOPICS
from conveyor_twin.record import reader, topics as contract
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.ros.record_node import message_class, RecordNode
from conveyor_twin.wire import cdr

from conveyor_twin.testing import wait_for

pytestmark = pytest.mark.ros

DT_NS = 1_000_000
# keep-all reliable writers: a burst is never overwritten before the recorder has it
RELIABLE_ALL = QoSProfile(history=HistoryPolicy.KEEP_ALL,
                          reliability=ReliabilityPolicy.RELIABLE)
CLOCK_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)


def step_messages(step):
    """Return {contract name: cdr bytes} of one synthetic step (at time step + 1 [ms])."""
    t = (step + 1) * DT_NS
    n = 1 + step % 4
    ids = list(range(1, n + 1))
    return {
        '/clock': cdr.encode_clock(t),
        'belt_states': cdr.encode_belt_states(t, 'cell', ('main',), [0.5], [0.4 + 1e-3 * step]),
        'parts': cdr.encode_part_states(t, 'cell', step, ids, [0] * n, [0.01 * step] * n,
                                        [0.0] * n, [0.0] * n, [0.5] * n, [0.0] * n, [0.0] * n),
        'light_barrier_edges': cdr.encode_light_barrier_edge(t - 300_000, 'cell', 'lb',
                                                             step % 2 == 0, step),
    }


class Publisher:
    """Publishers of the contract topics of :func:`step_messages`, in a namespace."""

    def __init__(self, context, namespace=''):
        import rclpy
        self.node = rclpy.create_node('test_publisher', context=context)
        self.pubs = {}
        for name in ('/clock', 'belt_states', 'parts', 'light_barrier_edges', 'belt_command'):
            spec = TOPICS[name]
            qos = CLOCK_QOS if name == '/clock' else RELIABLE_ALL
            self.pubs[name] = self.node.create_publisher(
                message_class(spec.type_name), contract.resolve(name, namespace), qos)

    def matched(self, names):
        return all(self.pubs[n].get_subscription_count() > 0 for n in names)


def test_record_node_round_trip(tmp_path, ros_context, ros_executor):
    path = str(tmp_path / 'live.mcap')
    pub = Publisher(ros_context, namespace='twin')
    ros_executor.add_node(pub.node)
    recorder = McapRecorder(path, decimation={'/twin/parts': 5})
    specs = contract.select(['/clock', 'belt_states', 'parts', 'light_barrier_edges',
                             'belt_command'])
    node = RecordNode(recorder, specs, namespace='twin', context=ros_context)
    ros_executor.add_node(node)
    assert wait_for(lambda: pub.matched(pub.pubs), 20.0, ros_executor)
    sent = {name: [] for name in pub.pubs}
    command = cdr.encode_belt_command('main', 0.25)
    steps = 40
    for step in range(steps):
        for name, data in step_messages(step).items():
            pub.pubs[name].publish(data)
            sent[name].append(data)
        if step == 20:  # a command arrives after the clock of step 20: logged at 21 ms
            assert wait_for(lambda: node.counts['/clock'].received == 21, 10.0, ros_executor)
            pub.pubs['belt_command'].publish(command)
            assert wait_for(lambda: node.counts['/twin/belt_command'].received == 1, 10.0,
                            ros_executor)
        wait_for(lambda: node.counts['/clock'].received > step, 0.2, ros_executor)
    assert wait_for(lambda: all(node.counts[contract.resolve(n, 'twin')].received == steps
                                for n in ('belt_states', 'parts', 'light_barrier_edges')),
                    10.0, ros_executor)
    stats = recorder.close()
    assert stats.topics['/twin/parts'].recorded == steps // 5
    assert stats.topics['/twin/parts'].decimated == steps - steps // 5
    got = {}
    for m in reader.read_messages(path):
        got.setdefault(m.topic, []).append(m)
    for name in ('belt_states', 'light_barrier_edges', '/clock'):
        topic = contract.resolve(name, 'twin')
        if name == '/clock':  # best effort: whatever came, in order
            remaining = iter(sent[name])
            assert all(any(m.data == d for d in remaining) for m in got[topic])
            assert len(got[topic]) >= 0.9 * steps
        else:
            assert sorted(m.data for m in got[topic]) == sorted(sent[name]), name
        for m in got[topic]:  # log time = the stamp in the message
            assert m.log_time == contract.stamp_ns(Stamp.HEADER, m.data)
    assert [m.data for m in got['/twin/parts']] == sent['parts'][::5]
    [cmd] = got['/twin/belt_command']
    assert cmd.data == command and cmd.log_time == 21 * DT_NS
    assert reader.info(path)['topics']['/twin/belt_states']['type'] == \
        'conveyor_twin_msgs/msg/BeltStates'
    assert node.counts['/twin/belt_states'].gaps() == 0


def test_record_process_stops_cleanly_on_sigint(tmp_path, ros_context, ros_executor,
                                                ros_processes):
    path = str(tmp_path / 'sigint.mcap')
    pub = Publisher(ros_context)
    ros_executor.add_node(pub.node)
    process = ros_processes.start(
        [sys.executable, '-m', 'conveyor_twin.cli', 'record', '-o', path, '--topics',
         'belt_states', 'parts', '/clock', '--decimate', 'parts=4', '--compression', 'zstd'],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    names = ('belt_states', 'parts', '/clock')
    assert wait_for(lambda: pub.matched(names) or process.poll() is not None, 30.0,
                    ros_executor)
    assert process.poll() is None, process.stdout.read()
    steps = 400
    sent = {name: [] for name in names}
    start = time.monotonic()
    for step in range(steps):  # paced like a twin at 500 Hz
        for name, data in step_messages(step).items():
            if name in names:
                pub.pubs[name].publish(data)
                sent[name].append(data)
        delay = start + (step + 1) * 0.002 - time.monotonic()
        if delay > 0:
            time.sleep(delay)

    def recorded():
        counts = {}
        try:
            for m in reader.read_messages(path, linear=True):  # the file grows, unclosed
                counts[m.topic] = counts.get(m.topic, 0) + 1
        except Exception:  # noqa: BLE001 - a chunk being written
            return {}
        return counts

    # the timed flush makes everything reach the file while the recorder runs
    assert wait_for(lambda: recorded().get('/belt_states') == steps
                    and recorded().get('/parts') == steps // 4, 20.0), recorded()
    assert not reader.is_complete(path)
    os.kill(process.pid, signal.SIGINT)
    assert wait_for(lambda: process.poll() is not None, 20.0), 'recorder ignores SIGINT'
    out = process.stdout.read()
    assert process.returncode == 0, out
    assert reader.is_complete(path)
    info = reader.info(path)
    assert info['topics']['/belt_states']['count'] == steps
    assert info['topics']['/parts']['count'] == steps // 4
    assert info['compression'] == ['zstd']
    clock_count = info['topics']['/clock']['count']
    assert clock_count >= 0.9 * steps
    data = [m.data for m in reader.read_messages(path, topics=['/belt_states'])]
    assert data == sent['belt_states']
    line = next(ln for ln in out.splitlines() if ln.strip().startswith('/belt_states'))
    assert line.split()[1:] == [str(steps), str(steps), '0', '0', '0']
    line = next(ln for ln in out.splitlines() if ln.strip().startswith('/parts'))
    assert line.split()[1:4] == [str(steps), str(steps // 4), str(steps - steps // 4)]
    assert '/clock' in out and str(clock_count) in out


def test_the_command_lines_reach_the_recorders_as_options(monkeypatch, capsys):
    from conveyor_twin.cli import record as cli_record
    from conveyor_twin.cli.run import build_parser
    from conveyor_twin.ros import record_node
    from conveyor_twin.ros.run_recording import RecordingOptions

    got = []
    monkeypatch.setattr(record_node, 'record', lambda options: got.append(options) or 0)
    assert cli_record.main(['-o', 'x.mcap', '--namespace', 'twin', '--topics', 'parts',
                            '--decimate', 'parts=4', '--compression', 'zstd']) == 0
    [options] = got
    assert [s.name for s in options.specs] == ['parts']
    assert options.decimation == {'/twin/parts': 4}
    assert (options.output, options.namespace, options.compression) == ('x.mcap', 'twin',
                                                                        'zstd')
    assert cli_record.main(['-o', 'x.mcap', '--decimate', 'parts=0']) == 2 and len(got) == 1
    assert 'expected NAME=K' in capsys.readouterr().err
    args = build_parser().parse_args(
        ['--cell', 'c.yaml', '--record', 'r.mcap', '--record-topics', 'parts',
         '--record-decimate', 'parts=10', '--record-queue-size', '3', '--command',
         '5:belt:main=1'])
    assert cli_record.recording_options(args) == RecordingOptions(
        path='r.mcap', topics=['parts'], decimate=['parts=10'], queue_size=3,
        commands=['5:belt:main=1'], cell_file='c.yaml', markers_rate=30.0)
