"""``conveyor-twin replay`` as a child process, listened to by a raw probe in this process."""

import pathlib
import subprocess
import sys
import time

import numpy as np
import pytest

from conveyor_twin.bench.cpu import cpu_times, steal_percent
from conveyor_twin.record import reader
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


def pacing_errors(probe, sent, rate):
    """Return |arrival - schedule| [ms] of every belt_states message, and the arrival span [s]."""
    arrivals = probe.received[BELT]
    expected = [(t, data) for topic, t, data in sent if topic == BELT]
    assert [d for _, d in arrivals] == [d for _, d in expected]
    recv = np.array([t for t, _ in arrivals], dtype=np.int64)
    log = np.array([t for t, _ in expected], dtype=np.int64)
    # arrival minus schedule, anchored at the typical offset (not at the first message, whose
    # own delivery delay would otherwise shift every error): jitter and drift remain
    offset = (recv - log / rate).astype(np.float64)
    err = offset - np.median(offset)
    print(f'offset of the first message from the typical one: {err[0] / 1e6:.3f} ms')
    return np.abs(err) / 1e6, (recv[-1] - recv[0]) / 1e9


def describe(errors_ms):
    return (f'median {np.median(errors_ms):.3f} ms, p90 {np.percentile(errors_ms, 90):.3f} ms, '
            f'p99 {np.percentile(errors_ms, 99):.3f} ms, max {errors_ms.max():.3f} ms '
            f'over {len(errors_ms)} messages')


def run_paced(tmp_path, ros_context, executor, ros_processes, seconds, rate):
    path = tmp_path / f'belts_{time.monotonic_ns()}.mcap'
    sent = belt_clock(str(path), seconds)
    count = sum(1 for topic, _, _ in sent if topic == BELT)
    probe = start_probe(executor, ros_context, ['belt_states', '/clock'])
    process = replay(ros_processes, path, '--rate', str(rate))
    started = time.monotonic()
    spin_until(executor, lambda: probe.count(BELT) >= count,
               START_TIMEOUT + seconds / rate * 2)
    out = finish(executor, process)
    print(f'replay of {seconds} s at rate {rate} took {time.monotonic() - started:.2f} s '
          f'with start-up; replay says: {out.splitlines()[1]}')
    errors, span = pacing_errors(probe, sent, rate)
    executor.remove_node(probe)
    probe.destroy_node()
    print(f'pacing error at rate {rate}: {describe(errors)}; span {span:.4f} s')
    return errors, span


# Bounds: the pacing error of a typical message within 1 ms (the contract of a 1 kHz twin);
# the tail is left to the machine (shared, 2 cores, other test suites running), but a replay
# that drifts or sleeps in whole scheduler ticks fails the median and the span.
MEDIAN_BOUND_MS = 1.0
P99_BOUND_MS = 50.0
# A replay starved of the CPU by other jobs on the shared machine shows it in its own lateness;
# the pacing is judged on the best of this many runs, each printed with the hypervisor's steal
# share meanwhile, so a starved run is retried rather than hidden, and a replay that is slow
# every time still fails. (A fresh-clone CI run once saw three starved attempts in a row:
# median 5.5 ms, p90 17 ms; the same test passed at once right after.)
ATTEMPTS = 5


def best_paced(check, *args):
    """Run :func:`run_paced` until ``check(errors, span)`` holds; raise the last failure."""
    for attempt in range(1, ATTEMPTS + 1):
        before = cpu_times()
        errors, span = run_paced(*args)
        steal = steal_percent(before, cpu_times())
        try:
            check(errors, span)
            return
        except AssertionError:
            print(f'attempt {attempt} of {ATTEMPTS} missed the bounds (steal {steal} %)')
            if attempt == ATTEMPTS:
                raise


@pytest.mark.slow
def test_replay_keeps_the_recorded_timing(tmp_path, ros_context, executor, ros_processes):
    def check(errors, span):
        assert np.median(errors) <= MEDIAN_BOUND_MS, describe(errors)
        assert np.percentile(errors, 99) <= P99_BOUND_MS, describe(errors)
        assert span == pytest.approx(9.999, abs=0.03)  # no drift over 10 s

    best_paced(check, tmp_path, ros_context, executor, ros_processes, 10.0, 1.0)


def test_rate_2_halves_the_duration(tmp_path, ros_context, executor, ros_processes):
    def check(errors, span):
        assert span == pytest.approx(1.999 / 2, abs=0.03)
        assert np.median(errors) <= MEDIAN_BOUND_MS, describe(errors)

    best_paced(check, tmp_path, ros_context, executor, ros_processes, 2.0, 2.0)


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
