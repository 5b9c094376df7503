"""``conveyor-twin replay`` as a child process, listened to by a raw probe in this process."""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from conveyor_twin.record import reader
from conveyor_twin.ros import replay as replay_module
from conveyor_twin.record.topics import stamp_ns
from conveyor_twin.wire.cdr import decode_clock

from .raw_probe import events_executor, RawProbe, spin_until
from ..record.helpers import record_run
from ..record.synthetic import belt_clock

pytestmark = pytest.mark.ros

BELT = '/belt_states'
CLOCK = '/clock'
START_TIMEOUT = 30.0  # discovery, interpreter start-up [s]
# The replay sees its writers match the probe before the probe's readers match the writers; a
# sample sent in between is lost even on reliable topics (Fast DDS 3.2, volatile durability),
# so the replay waits this long after matching (its --delay option) [s].
SETTLE = 2.0  # s after matching before the first message (see replay --delay)


@pytest.fixture
def executor(ros_context):
    ex = events_executor(ros_context)
    yield ex
    for node in list(ex.get_nodes()):
        ex.remove_node(node)
        node.destroy_node()
    ex.shutdown()


def start_probe(executor, context, names):
    probe = RawProbe(context, names)
    executor.add_node(probe)
    return probe


def replay(ros_processes, path, *options):
    return ros_processes.start(
        [sys.executable, '-m', 'conveyor_twin.cli', 'replay', str(path),
         '--wait-for-subscribers', str(START_TIMEOUT), '--delay', str(SETTLE), *options],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def finish(executor, process, timeout=30.0):
    """Spin until the replay process exits; return its output (it must exit with 0)."""
    assert spin_until(executor, lambda: process.poll() is not None, timeout), 'replay hangs'
    out = process.stdout.read()
    assert process.returncode == 0, out
    return out


def is_subsequence(part, whole):
    it = iter(whole)
    return all(any(x == y for y in it) for x in part)


def test_replay_republishes_every_message_with_identical_bytes(
        tmp_path, ros_context, executor, ros_processes):
    path = tmp_path / 'run.mcap'
    _, sent = record_run(str(path), steps=300)
    streams = ['parts', 'density', 'light_barriers', 'light_barrier_edges', 'belt_states',
               'actuator_states']
    probe = start_probe(executor, ros_context, streams + ['/clock', 'belt_command',
                                                          'actuator_command'])
    process = replay(ros_processes, path)
    done = spin_until(executor, lambda: all(
        probe.count('/' + s) >= len(sent['/' + s]) for s in streams), START_TIMEOUT + 10)
    out = finish(executor, process)
    assert done, {s: probe.count('/' + s) for s in streams}
    for s in streams:  # reliable: all of them, in order, byte for byte
        assert probe.data('/' + s) == [data for _, data, _ in sent['/' + s]], s
    clock = probe.data(CLOCK)  # best effort: in order, nearly all
    assert is_subsequence(clock, [data for _, data, _ in sent[CLOCK]])
    assert len(clock) >= 0.9 * len(sent[CLOCK])
    # the accepted commands are in the file but not republished as commands
    assert len(sent['/conveyor_twin/accepted/belt_command']) == 2
    assert probe.count('/belt_command') == probe.count('/actuator_command') == 0
    assert 'published' in out and '/conveyor_twin/accepted' not in out


class _Publisher:
    def __init__(self, topic, log):
        self.topic, self.log = topic, log

    def publish(self, data):
        self.log.append((self.topic, bytes(data)))


class _Node:
    """Stands in for an rclpy node: its publishers log what they are given."""

    def __init__(self):
        self.log = []

    def create_publisher(self, msg_type, topic, qos):
        return _Publisher(topic, self.log)


@pytest.mark.parametrize('rate, loop', [(1.0, False), (2.0, False), (0.5, False), (1.0, True)])
def test_every_message_is_published_on_its_recorded_deadline(tmp_path, monkeypatch, rate, loop):
    """The replay's schedule, read from the deadlines it waits for (no wall clock): message k
    at t0 + (log time k - first log time) / rate; a loop starts one period after the last."""
    path = tmp_path / 'belts.mcap'
    sent = belt_clock(str(path), 0.05)
    deadlines = []

    def wait(deadline_ns, spin_margin_ns):
        deadlines.append(deadline_ns)
        return 0

    monkeypatch.setattr(replay_module, 'wait_until', wait)
    node = _Node()
    replayer = replay_module.Replayer(node, replay_module.plan(str(path)), rate=rate, loop=loop)
    if loop:  # stop during the second pass
        original = wait

        def wait(deadline_ns, spin_margin_ns):
            if len(deadlines) == 1.5 * len(sent):
                replayer.stop()
            return original(deadline_ns, spin_margin_ns)

        monkeypatch.setattr(replay_module, 'wait_until', wait)
    stats = replayer.run()
    passes = 2 if loop else 1
    count = len(deadlines)
    assert node.log == [(topic, data) for topic, _, data in sent * passes][:count]
    log = np.array([t for _, t, _ in sent * passes][:count], dtype=np.int64)
    if loop:  # the second pass goes on one period (1 ms) after the last message of the first
        log[len(sent):] += log[len(sent) - 1] + 1_000_000
    expected = (log - log[0]) / rate
    assert np.array_equal(np.array(deadlines) - deadlines[0], expected.astype(np.int64))
    assert sum(stats.published.values()) == count
    assert stats.loops == (1 if loop else 0)


def test_a_live_replay_never_runs_ahead_of_the_recording(tmp_path, ros_context, executor,
                                                         ros_processes):
    """Over ROS, at rates 1 and 2: every message arrives, in order, and the replay takes at
    least the recorded span over the rate (it may only be late, never early)."""
    for rate in (1.0, 2.0):
        path = tmp_path / f'belts_{rate:g}.mcap'
        sent = belt_clock(str(path), 2.0)
        expected = [data for topic, _, data in sent if topic == BELT]
        probe = start_probe(executor, ros_context, ['belt_states', '/clock'])
        process = replay(ros_processes, path, '--rate', str(rate), '--json')
        spin_until(executor, lambda: probe.count(BELT) >= len(expected),
                   START_TIMEOUT + 2.0 / rate * 10)
        out = finish(executor, process)
        summary = json.loads(out.strip().splitlines()[-1])
        assert probe.data(BELT) == expected
        assert summary['published'][BELT] == len(expected)
        span = (sent[-1][1] - sent[0][1]) / 1e9
        assert summary['wall_s'] >= span / rate
        executor.remove_node(probe)
        probe.destroy_node()


def test_start_offset_skips_and_topics_filter(tmp_path, ros_context, executor, ros_processes):
    path = tmp_path / 'run.mcap'
    _, sent = record_run(str(path), steps=400)
    probe = start_probe(executor, ros_context, ['belt_states', 'parts', 'light_barriers',
                                                '/clock'])
    process = replay(ros_processes, path, '--start-offset', '0.25', '--topics', 'belt_states')
    expected = [data for t, data, _ in sent[BELT] if t >= 250_000_000]
    assert len(expected) == 150
    spin_until(executor, lambda: probe.count(BELT) >= len(expected), START_TIMEOUT + 10)
    finish(executor, process)
    assert probe.data(BELT) == expected
    assert probe.count('/parts') == probe.count('/light_barriers') == 0
    clock = [decode_clock(d) for d in probe.data(CLOCK)]
    assert clock and min(clock) >= 250_000_000 and clock == sorted(clock)


def test_clock_is_synthesised_from_log_times(tmp_path, ros_context, executor, ros_processes):
    path = tmp_path / 'no_clock.mcap'
    sent = belt_clock(str(path), 0.5, clock=False)
    assert '/clock' not in reader.info(str(path))['topics']
    probe = start_probe(executor, ros_context, ['belt_states', '/clock'])
    process = replay(ros_processes, path)
    spin_until(executor, lambda: probe.count(BELT) >= len(sent), START_TIMEOUT + 10)
    finish(executor, process)
    clock = [decode_clock(d) for d in probe.data(CLOCK)]
    stamps = [stamp_ns('header', d) for d in probe.data(BELT)]
    assert stamps == [t for _, t, _ in sent]
    assert is_subsequence(clock, stamps) and len(clock) >= 0.9 * len(stamps)


@pytest.mark.smoke
def test_replay_of_a_reference_bag(ros_context, executor, ros_processes):
    """bags/default_4s.mcap (a ``run --record`` recording) replays byte for byte."""
    path = pathlib.Path(__file__).resolve().parents[2] / 'bags' / 'default_4s.mcap'
    start = next(reader.read_messages(str(path))).log_time + 3_500_000_000  # from the first
    expected = {topic: [m.data for m in reader.read_messages(str(path), topics=[topic])
                        if m.log_time >= start]
                for topic in (BELT, '/light_barrier_edges', '/parts')}
    assert len(expected[BELT]) == 500 and expected['/light_barrier_edges']
    probe = start_probe(executor, ros_context, ['belt_states', 'light_barrier_edges', 'parts',
                                                '/clock'])
    process = replay(ros_processes, path, '--start-offset', '3.5', '--topics', 'belt_states',
                     'light_barrier_edges', 'parts')
    spin_until(executor, lambda: all(probe.count(t) >= len(d) for t, d in expected.items()),
               START_TIMEOUT + 10)
    finish(executor, process)
    for topic, data in expected.items():
        assert probe.data(topic) == data, topic


def test_the_command_line_reaches_the_replay_as_options(monkeypatch, capsys):
    from conveyor_twin.cli import replay as cli_replay
    from conveyor_twin.ros import replay as ros_replay

    got = []
    monkeypatch.setattr(ros_replay, 'replay', lambda options: got.append(options) or 0)
    assert cli_replay.main(['run.mcap', '--rate', '2', '--loop', '--no-clock', '--topics',
                            'parts', '--linger', '1', '--json']) == 0
    assert got == [ros_replay.ReplayOptions(file='run.mcap', rate=2.0, loop=True,
                                            topics=['parts'], clock=False, linger=1.0,
                                            json=True)]
    assert cli_replay.main(['run.mcap', '--start-offset', '-1']) == 2 and len(got) == 1
    assert '--rate must be > 0 and --start-offset >= 0' in capsys.readouterr().err
