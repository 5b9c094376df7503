"""A recording process killed with SIGKILL loses at most the flush period + 2 steps."""

import os
import pathlib
import signal
import subprocess
import sys
import time

from conveyor_twin.record import reader
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
DT_NS = 1_000_000
FLUSH_PERIOD = 0.1
KILL_AFTER_STEPS = 700


@pytest.mark.slow
def test_sigkill_loses_at_most_one_flush_period(tmp_path):
    path = tmp_path / 'killed.mcap'
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    child = subprocess.Popen(
        [sys.executable, str(ROOT / 'test' / 'record' / 'kill_writer.py'), str(path),
         str(FLUSH_PERIOD)], stdout=subprocess.PIPE, text=True, env=env)
    last_step = -1
    deadline = time.monotonic() + 60
    try:
        for line in child.stdout:
            last_step = int(line)
            if last_step >= KILL_AFTER_STEPS or time.monotonic() > deadline:
                break
        child.send_signal(signal.SIGKILL)
    finally:
        child.kill()
        child.wait(10)
        child.stdout.close()
    assert child.returncode == -signal.SIGKILL
    assert last_step >= KILL_AFTER_STEPS, 'the writer did not reach the kill point in time'

    report = reader.recover(path, tmp_path / 'recovered.mcap')
    assert not report.complete_source and report.damaged == []
    lost_steps = last_step - report.last_time // DT_NS
    print(f"killed at step >= {last_step}, last recovered step {report.last_time // DT_NS}")
    assert lost_steps <= FLUSH_PERIOD * 1e9 / DT_NS + 2, (last_step, report)
    clock = [m.log_time // DT_NS
             for m in reader.read_messages(tmp_path / 'recovered.mcap', topics=['/clock'])]
    assert clock == list(range(len(clock)))  # every step up to the last recovered one
    assert report.messages['/parts'] == report.messages['/clock'] == len(clock)
    summary = reader.info(tmp_path / 'recovered.mcap')
    assert summary['complete'] and summary['cell_name'] == 'kill_test'
