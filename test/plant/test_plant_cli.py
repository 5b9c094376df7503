"""`conveyor-twin plant` as a user runs it: the `--processes` parent supervises its cells (a
cell that dies is named with its exit status and last output, the others run on, a restart on
request), progress after a restart counts the plant's time on, `--json` prints only JSON."""

import json
import os
from pathlib import Path
import queue
import re
import signal
import subprocess
import sys
import threading
from typing import Callable, List

import pytest

RES = Path(__file__).resolve().parents[1] / 'resources' / 'plant'
CHAIN = RES / 'chain.yaml'
TIMEOUT = 240.0         # s, a bound for a loaded machine, not a speed requirement

pytestmark = pytest.mark.ros


def cli(*args: str) -> list:
    return [sys.executable, '-m', 'conveyor_twin.cli', 'plant', *args]


class Lines:
    """Every line a stream gives, read by a thread; wait for one that matches."""

    def __init__(self, stream) -> None:
        self.seen: List[str] = []
        self._q: 'queue.Queue[str]' = queue.Queue()
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream) -> None:
        for line in stream:
            self._q.put(line.rstrip('\n'))

    def wait(self, match: Callable[[str], bool], what: str) -> str:
        import time
        deadline = time.monotonic() + TIMEOUT
        while time.monotonic() < deadline:
            try:
                line = self._q.get(timeout=1.0)
            except queue.Empty:
                continue
            self.seen.append(line)
            if match(line):
                return line
        raise AssertionError(f'no line {what} in {TIMEOUT} s:\n' + '\n'.join(self.seen[-40:]))


def cell_pid(parent: int, cell: str) -> int:
    """The pid of the parent's child process that runs ``cell``."""
    with open(f'/proc/{parent}/task/{parent}/children') as f:
        children = [int(p) for p in f.read().split()]
    for pid in children:
        with open(f'/proc/{pid}/cmdline', 'rb') as f:
            args = f.read().split(b'\0')
        if b'--cell' in args and args[args.index(b'--cell') + 1] == cell.encode():
            return pid
    raise AssertionError(f'no process of cell {cell!r} among {children}')


def progress(line: str) -> dict:
    """The plant time [s] and the cells' steps of a progress line."""
    m = re.search(r'plant at +([0-9.]+) s  steps (.*?)  entered', line)
    assert m, line
    return {'time': float(m.group(1)), 'cells': m.group(2)}


def is_progress(line: str) -> bool:
    return ' plant at ' in line


def test_the_parent_restarts_a_dead_cell_once_then_keeps_the_others_running(ros_processes):
    proc = ros_processes.start(cli(str(CHAIN), '--no-streams', '--duration', '0',
                                   '--restart-dead', '1', '--json'),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    err = Lines(proc.stderr)
    # every cell has stepped: the plant runs
    err.wait(lambda x: is_progress(x) and progress(x)['time'] > 0, 'with the plant running')
    os.kill(cell_pid(proc.pid, 'second'), signal.SIGKILL)
    err.wait(lambda x: "cell 'second' died (exit status -9 (killed by SIGKILL))" in x,
             'naming the dead cell')
    err.wait(lambda x: "starting cell 'second' again (restart 1 of 1)" in x, 'on the restart')
    # the new run reports: its steps count from 0, the plant's time does not
    line = err.wait(lambda x: is_progress(x) and 'second:' in x and '(run 2)' in x,
                    'with the second run')
    assert progress(line)['time'] > 0, line
    os.kill(cell_pid(proc.pid, 'second'), signal.SIGKILL)
    err.wait(lambda x: "cell 'second' stays dead; the other cells run on" in x, 'dead')
    line = err.wait(lambda x: is_progress(x) and '(run 2 dead)' in x, 'with the dead cell')
    before = progress(line)
    # the cells upstream run on: the middle cell's link has no capacity
    err.wait(lambda x: is_progress(x) and re.search(r'first:(\d+)', x) and int(
        re.search(r'first:(\d+)', x).group(1)) > int(re.search(r'first:(\d+)',
                                                               line).group(1)),
             'with the middle cell further on')
    assert before['time'] >= 0
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 3
    summary = json.loads(out)                  # the summary is the only output on stdout
    assert summary['restarts'] == {'feeder': 0, 'first': 0, 'second': 1}
    assert summary['dead'] == ['second']
    assert [f.split(':')[0] for f in summary['failures']] == [
        "cell 'second' process (run 1)", "cell 'second' process (run 2)"]
    assert 'exit status -9 (killed by SIGKILL)' in summary['failures'][0]


def test_json_output_is_only_json(ros_processes):
    proc = ros_processes.start(cli(str(CHAIN), '--composed', '--no-streams', '--duration',
                                   '0.3', '--json'),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, err
    summary = json.loads(out)
    assert summary['steps'] == {'feeder': 300, 'first': 300, 'second': 300}
    assert summary['failures'] == [] and ' plant at ' in err     # progress on stderr


def test_a_negative_restart_count_is_refused():
    proc = subprocess.run(cli(str(CHAIN), '--restart-dead', '-1'), capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2 and proc.stdout == ''
    assert '--restart-dead: got -1; expected an integer >= 0' in proc.stderr


def test_the_monitor_says_once_per_run_that_a_cell_left_before_its_done_report(capsys):
    from types import SimpleNamespace

    from conveyor_twin.cli.plant import _warn_gone, GONE_AFTER

    class Monitor:
        gone: List[str] = []
        reports = {'second': SimpleNamespace(run=1, step=812)}

        def gone_unfinished(self) -> List[str]:
            return list(self.gone)
    monitor, said = Monitor(), {}
    _warn_gone(monitor, said, 10.0)                 # present: nothing to say
    monitor.gone = ['second']
    _warn_gone(monitor, said, 11.0)                 # missed from now on
    _warn_gone(monitor, said, 11.0 + GONE_AFTER / 2)
    assert capsys.readouterr().err == ''
    for t in (11.0 + GONE_AFTER, 30.0, 60.0):      # gone long enough: said once
        _warn_gone(monitor, said, t)
    assert capsys.readouterr().err == (
        "conveyor-twin plant: cell 'second' (run 1) left at step 812 before its done report "
        "arrived; waiting for it to run again\n")
    monitor.reports['second'] = SimpleNamespace(run=2, step=40)   # restarted, gone again
    _warn_gone(monitor, said, 70.0)
    _warn_gone(monitor, said, 70.0 + GONE_AFTER)
    assert "cell 'second' (run 2) left at step 40" in capsys.readouterr().err
