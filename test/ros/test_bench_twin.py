"""``conveyor-twin bench twin`` end to end, short: both readers measure every stream.

The figures themselves (rates, overruns) depend on the machine and are not asserted; what is
pinned is that the benchmark places its parts, measures all five streams in sim-time order with
either reader, reports the reader's own CPU share, and sums the rounds up: the twin/floor ratio
of each round, their median and the messages lost per stream.
"""

import json
import subprocess
import sys

import pytest

from conveyor_twin.bench.twin import free_places, lattice, refused_entries, STREAMS
from conveyor_twin.testing import ros_subprocess_env


@pytest.mark.parametrize('reader', ['poll', 'callback'])
def test_bench_twin_measures_every_stream(reader):
    argv = [sys.executable, '-m', 'conveyor_twin.cli', 'bench', 'twin', '--duration', '2',
            '--settle', '0.5', '--parts', '100', '--reader', reader, '--floor-window', '0.5',
            '--json']
    done = subprocess.run(argv, env=ros_subprocess_env(), capture_output=True, text=True,
                          timeout=240)
    assert done.returncode == 0, done.stderr[-2000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    (figures,) = report['layouts']
    assert 'error' not in figures, figures
    assert figures['placed_parts'] == 100
    assert figures['reader'] == reader and 0.0 < figures['subscriber_cpu_share'] < 2.0
    assert set(figures['streams']) == set(STREAMS)
    for topic, stream in figures['streams'].items():
        # a realtime twin sends ~2000 per stream in 2 s; 100 leaves room for a loaded machine
        assert stream['messages'] >= 100, (topic, stream)
        assert stream['out_of_order'] == 0, (topic, stream)
        assert stream['interarrival_p50_ms'] > 0.0, (topic, stream)
    assert figures['twin_summary']['steps'] > 0
    # the slowest step of the window and its parts; the late seconds counted by part
    assert figures['slowest_step_ms'] > 0.0
    assert 'micro ' in figures['slowest_step_parts_ms']
    assert 0.0 < figures['slowest_step_cpu_ms'] <= figures['slowest_step_ms'] + 0.01
    assert set(figures['late_seconds_by_cause']) <= {'commands', 'micro', 'macro', 'hand-over',
                                                     'outputs', 'waited for the CPU',
                                                     'started late'}
    assert figures['latest_wake_ms'] >= 0.0
    # the paced floor ran before and after the twin's window, 500 deadlines each
    windows = figures['floor']['windows']
    assert [w['steps'] for w in windows] == [500, 500], windows
    assert figures['overruns_per_min'] >= 0 and figures['floor']['overruns_per_min'] >= 0
    assert figures['load_average'] >= 0.0
    # the summary over rounds: the ratio of every round and their median, losses per stream
    (summary,) = report['rounds'].values()
    assert len(summary['ratios']) == 1 and summary['errors'] == 0
    ratio = summary['ratios'][0]
    assert summary['median_ratio'] == (None if ratio is None else pytest.approx(ratio))
    assert set(summary['lost']) == set(STREAMS)  # /clock included
    assert summary['lost_total'] == sum(summary['lost'].values())
    assert summary['lost'] == {t: s['lost'] for t, s in figures['streams'].items()}


def test_late_seconds_are_counted_by_the_cause_of_their_slowest_step():
    from conveyor_twin.bench.twin_window import late_steps_by_cause

    def second(overruns, slowest, cpu, parts, wake=0.01):
        return {'overruns': str(overruns), 'slowest_step_ms': str(slowest),
                'slowest_step_cpu_ms': str(cpu), 'slowest_step_parts_ms': parts,
                'latest_wake_ms': str(wake)}

    figures = late_steps_by_cause([second(0, 0.2, 0.2, 'micro 0.150, outputs 0.050'),
                           second(2, 1.3, 1.25, 'micro 1.200, outputs 0.100'),
                           second(2, 0.9, 0.9, 'outputs 0.600, micro 0.300'),
                           second(3, 1.1, 1.0, 'outputs 0.700, hand-over 0.400'),
                           second(4, 0.7, 0.7, 'micro 0.500, outputs 0.200', wake=0.6),
                           second(5, 1.2, 1.1, 'micro 1.100, outputs 0.100'),
                           second(9, 7.3, 0.4, 'micro 7.100, outputs 0.200')])
    assert figures == {'late_seconds_by_cause': {'micro': 2, 'outputs': 1, 'started late': 1,
                                                 'waited for the CPU': 1},
                       'slowest_step_ms': 7.3, 'slowest_step_cpu_ms': 0.4,
                       'slowest_step_parts_ms': 'micro 7.100, outputs 0.200',
                       'latest_wake_ms': 0.6}
    # a step that fits in a longer period cannot overrun on its own either
    assert late_steps_by_cause([second(0, 0.2, 0.2, 'micro 0.2'),
                                second(1, 1.3, 1.25, 'micro 1.300')], period_ms=2.0
                               )['late_seconds_by_cause'] == {'started late': 1}


def test_refused_entries_of_both_messages():
    assert refused_entries('overlap: entries [3, 5] overlap a part') == [3, 5]
    assert refused_entries("part 17 (spacer) at x = 2.79 m, y = 0.2 m overlaps deflector "
                           "'deflector'; nothing placed") == [17]
    assert refused_entries('capacity exhausted') == []


def test_free_places_are_accepted_by_the_spawn_check():
    from conveyor_twin.cell import load_cell
    from conveyor_twin.coord.requests import check_spawn
    xy = lattice(2000)  # as the benchmark's 1000 parts: up to x = 5.7 m
    free = free_places(xy)
    assert 0 < free.shape[1] < xy.shape[1]  # the lattice crosses the deflector
    check_spawn(load_cell(None), 'spacer', free[0], free[1], [])  # raises if one is refused
