"""``bench plc``: the summary's arithmetic, and a brief run's output shape (no timing
asserts)."""

import json
import subprocess
import sys

import pytest

from conveyor_twin.bench import plc as bench


def test_latencies_pair_each_write_with_its_protocols_command():
    result = {'count': 500, 'seconds': 2.0, 'writes': [1_000_000, 101_000_000]}
    applied = [(2_500_000, 'modbus'), (3_000_000, 'opcua'), (104_000_000, 'modbus')]
    figures = bench._client_figures('modbus', result, applied)
    assert figures['polls_per_s'] == 250.0
    assert figures['writes'] == figures['writes_applied'] == 2
    assert figures['latency_p50_ms'] == pytest.approx(2.25)
    assert figures['latency_p99_ms'] == pytest.approx(3.0)


def test_the_summary_takes_medians_and_per_round_ratios():
    windows = []
    for r, (none, opcua) in enumerate(((0.10, 0.11), (0.20, 0.21), (0.10, 0.13))):
        windows.append({'round': r, 'variant': 'none', 'step_mean_ms': none,
                        'step_p50_ms': none, 'step_p99_ms': 2 * none, 'overruns': r})
        windows.append({'round': r, 'variant': 'opcua', 'step_mean_ms': opcua,
                        'step_p50_ms': opcua, 'step_p99_ms': 2 * opcua, 'overruns': 0,
                        'values_per_s': 100.0 * (r + 1)})
    summary = bench.summarize(windows)
    assert summary['none']['step_mean_ms'] == 0.10 and summary['none']['overruns'] == 1
    assert summary['opcua']['values_per_s'] == 200.0
    assert summary['opcua']['step_mean_ratio'] == pytest.approx(1.1)  # of 1.1, 1.05, 1.3
    assert summary['modbus'] == {}


@pytest.mark.ros
@pytest.mark.slow
def test_a_brief_run_reports_every_figure():
    done = subprocess.run([sys.executable, '-m', 'conveyor_twin.cli', 'bench', 'plc',
                           '--duration', '1', '--rounds', '1', '--json'],
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout.splitlines()[-1])
    assert [w['variant'] for w in report['windows']] == list(bench.VARIANTS)
    for w in report['windows']:
        assert w['steps'] == 1000 and w['step_p99_ms'] >= w['step_p50_ms'] > 0.0
    summary = report['summary']
    assert summary['opcua']['values_per_s'] > 0 and summary['modbus']['polls_per_s'] > 0
    for variant in ('opcua', 'modbus'):
        assert summary[variant]['latency_p99_ms'] >= summary[variant]['latency_p50_ms'] > 0
        assert summary[variant]['step_mean_ratio'] > 0
