"""SIGKILL of a recording twin (``conveyor-twin run --record``) at random times.

``recover`` must yield a valid file whose streams have no gap in ``step`` and whose loss is
within the flush period + 2 steps: every step that the twin had handed to the recorder more than
one flush period before its last step is in the recovered file (``kill_twin.py`` tells which
steps were handed over, and when, through a shared file that survives the kill), in fast mode
too, where the stepping thread never sleeps and the writer thread may get the GIL late: the
recorder then flushes from the stepping thread. The window ends at the last step the twin did
rather than at the kill: a process the machine does not run flushes nothing either.

Seeded: :data:`KILLS_PER_MODE` kills in each of realtime and fast mode (environment variable
``CONVEYOR_TWIN_KILLS_PER_MODE``, e.g. 50 for a long run under load).
"""

import os
import pathlib
import random
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from conveyor_twin.record import reader
from conveyor_twin.wire import cdr
from .kill_twin import RING
from conveyor_twin.testing import remove_dead_shm_files, RosProcesses
from conveyor_twin.testing.shm import SHM_MIN_AGE

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DT_NS = 1_000_000
FLUSH_PERIOD = 0.1  # s, the recorder's default
START_TIMEOUT = 60.0  # interpreter, numba cache and rclpy start-up under load [s]
SEED = 20261122
KILLS_PER_MODE = int(os.environ.get('CONVEYOR_TWIN_KILLS_PER_MODE', '5'))
rng = random.Random(SEED)
# (mode, kill at step >= this, extra delay after it [s]): seeded
CASES = [(mode, rng.randrange(150, 1500), rng.uniform(0.0, 0.003))
         for mode in ('realtime', 'fast') for _ in range(KILLS_PER_MODE)]


@pytest.fixture(scope='module', autouse=True)
def warm_numba_cache(ros_processes_module):
    """Run the twin once so that the killed children load compiled kernels from numba's cache
    (a kernel compiled in the middle of a run holds the GIL and starves the writer thread)."""
    child = ros_processes_module.start(
        [sys.executable, '-m', 'conveyor_twin.cli', 'run', '--mode', 'fast', '--duration', '0.3',
         '--quiet', '--markers-rate', '0'], stdout=subprocess.DEVNULL)
    child.wait(600)


@pytest.fixture(scope='module')
def ros_processes_module():
    processes = RosProcesses()
    yield processes
    processes.stop_all()


def probe_file(path):
    np.zeros(RING + 1, dtype='<i8').tofile(path)
    return np.memmap(path, dtype='<i8', mode='r', shape=(RING + 1,))


def steps_of(path, topic):
    if topic == '/parts':
        return [cdr.decode_part_states(m.data).step
                for m in reader.read_messages(path, topics=[topic])]
    return [m.log_time // DT_NS for m in reader.read_messages(path, topics=[topic])]


@pytest.mark.parametrize('mode,kill_step,delay', CASES,
                         ids=[f'{m}-{k}-{i}' for i, (m, k, _) in enumerate(CASES)])
def test_sigkill_recover_loses_at_most_a_flush_period(tmp_path, ros_processes, mode, kill_step,
                                                      delay):
    path, recovered = str(tmp_path / 'killed.mcap'), str(tmp_path / 'recovered.mcap')
    probe = probe_file(tmp_path / 'probe')
    child = ros_processes.start(
        [sys.executable, '-m', 'test.record.kill_twin', str(tmp_path / 'probe'),
         '--mode', mode, '--duration', '0', '--quiet', '--markers-rate', '0',
         '--record', path, '--record-flush-period', str(FLUSH_PERIOD),
         '--command', '100:belt:main=0.9'], stderr=open(tmp_path / 'stderr', 'w'))
    deadline = time.monotonic() + START_TIMEOUT
    while probe[0] < kill_step and child.poll() is None and time.monotonic() < deadline:
        time.sleep(0.0005)
    if probe[0] < kill_step and child.poll() is None:
        child.send_signal(signal.SIGUSR1)  # its threads' stacks, for the failure message
        time.sleep(1.0)
    time.sleep(delay)
    child.send_signal(signal.SIGKILL)
    kill_ns = time.monotonic_ns()
    child.wait(10)
    try:
        check_recovery(path, recovered, probe, child, mode, kill_step, kill_ns)
    finally:
        # Fast DDS's shared memory of the killed child: a later child may hang on it. It is
        # removable once SHM_MIN_AGE old.
        time.sleep(max(0.0, kill_ns * 1e-9 + SHM_MIN_AGE + 0.05 - time.monotonic()))
        remove_dead_shm_files()


def check_recovery(path, recovered, probe, child, mode, kill_step, kill_ns):
    """Check the recovered file against what the twin had handed to the recorder."""
    assert child.returncode == -signal.SIGKILL, 'the twin ended before the kill'
    last_done = int(probe[0])
    assert last_done >= kill_step, ('the twin did not reach the kill point in time:\n'
                                    + (pathlib.Path(path).parent / 'stderr').read_text())

    report = reader.recover(path, recovered)
    assert not report.complete_source
    assert reader.is_complete(recovered)
    clock = steps_of(recovered, '/clock')
    last = clock[-1] if clock else 0  # killed before the first flush: nothing, validly
    assert clock == list(range(1, last + 1))  # no gap in step
    for topic in ('/parts', '/belt_states', '/light_barriers', '/actuator_states'):
        steps = steps_of(recovered, topic)
        assert steps == list(range(1, len(steps) + 1)), topic
        assert abs(len(steps) - last) <= 1, topic
    # steps handed to the recorder in the last flush period before the kill
    done_at = {s: int(probe[1 + s % RING]) for s in range(max(1, last_done - RING + 1),
                                                          last_done + 1)}
    end_ns = min(kill_ns, done_at[last_done])
    recent = sum(1 for t in done_at.values() if t > end_ns - int(FLUSH_PERIOD * 1e9))
    lost = last_done - last
    print(f'{mode}: killed after step {last_done}, recovered up to {last}: lost {lost} steps '
          f'({recent} steps done in the last {FLUSH_PERIOD:.3f} s up to the last step)')
    assert lost <= recent + 2
    # what was recorded is intact: the accepted command and the cell travel with it
    commands = list(reader.read_messages(recovered,
                                         topics=['/conveyor_twin/accepted/belt_command']))
    assert [(m.log_time // DT_NS, cdr.decode_belt_command(m.data)) for m in commands] == \
        ([(100, ('main', 0.9))] if last >= 100 else [])
    assert reader.read_attachment(recovered, 'cell.yaml')
    assert reader.info(recovered)['seed'] == 1
