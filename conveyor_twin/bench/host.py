"""``conveyor-twin bench host``: how often can this machine give a 1 kHz loop its deadline?

The floor is a loop paced exactly like the twin's stepping thread but doing no work: a small C
program (``paced_floor.c``, built on first use with the system C compiler into ``build/`` of the
source tree, or the user's cache directory) that sleeps to absolute 1 ms deadlines with
``clock_nanosleep(TIMER_ABSTIME)``, wakes 150 us early and spins to the deadline, runs late steps
back to back, under SCHED_FIFO where permitted, and holding a request for zero CPU wake-up
latency where the twin's pacer would (``CONVEYOR_TWIN_CPU_LATENCY_REQUEST=1``). Every overrun it sees is time the kernel or (on a
virtual machine) the hypervisor did not give it, which no 1 kHz loop on the machine can avoid:
``bench twin`` reports the twin's overruns as a ratio to this floor, measured in windows
interleaved with the twin's.

``--work-ms W ...`` runs the same loop doing W ms of computation per step (passes over a
128 kB array, calibrated to take W ms at the median before the loop), one loop per value, their
windows interleaved: the overruns of a loop that works as long as the twin's step, which on a
virtual machine include the times its CPU runs slower than usual (a loop doing no work never
notices those).

``--loop busy`` measures the older figure instead: a thread that reads the monotonic clock in a
loop and never sleeps, counting the clock's jumps over 1 ms. Linux throttles real-time threads
that never sleep (by default to 95 % of each second: one ~50 ms gap per second) and
hypervisors deschedule busy guests more, so it overstates what a paced loop sees.
"""

import argparse
import hashlib
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Dict, List

import numpy as np

from conveyor_twin.bench.cpu import cpu_times, steal_percent

# gap classes [ms]: (low, high)
GAP_CLASSES = ((0.5, 1.0), (1.0, 2.0), (2.0, 5.0), (5.0, 20.0), (20.0, float('inf')))


def clock_gaps(seconds: float, threshold_ns: int = 100_000) -> np.ndarray:
    """Read the monotonic clock in a loop for ``seconds``; return the jumps above
    ``threshold_ns`` [ns]."""
    clock = time.monotonic_ns
    start = prev = clock()
    end = start + int(seconds * 1e9)
    gaps: List[int] = []
    while prev < end:
        now = clock()
        if now - prev > threshold_ns:
            gaps.append(now - prev)
        prev = now
    return np.asarray(gaps, dtype=np.int64)


def classify(gaps_ns: np.ndarray) -> Dict[str, int]:
    """Count gaps per class of :data:`GAP_CLASSES` and over 1 ms."""
    ms = gaps_ns * 1e-6
    out = {f'{lo:g}-{hi:g} ms' if hi != float('inf') else f'>{lo:g} ms':
           int(np.sum((ms > lo) & (ms <= hi))) for lo, hi in GAP_CLASSES}
    out['over_1ms'] = int(np.sum(ms > 1.0))
    return out


FLOOR_SOURCE = pathlib.Path(__file__).with_name('paced_floor.c')
#: SCHED_FIFO priority of the floor loop: the twin's stepping thread's default.
FLOOR_PRIORITY = 10
STEP_NS = 1_000_000


def _cache_dir() -> pathlib.Path:
    """Return the directory of the built helper: ``build/bench`` of the source tree when it is
    writable, else the user's cache directory."""
    root = pathlib.Path(__file__).resolve().parents[2]
    if (root / 'setup.py').exists() and os.access(root, os.W_OK):
        return root / 'build' / 'bench'
    base = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    return pathlib.Path(base) / 'conveyor_twin'


def floor_program() -> str:
    """Return the path of the compiled floor loop, building it first if needed.

    The binary's name carries a hash of the source, so an edited source is rebuilt.

    :raises RuntimeError: if no C compiler is found or the build fails (the message says why).
    """
    source = FLOOR_SOURCE.read_bytes()
    digest = hashlib.sha256(source).hexdigest()[:12]
    directory = _cache_dir()
    binary = directory / f'paced_floor-{digest}'
    if binary.exists():
        return str(binary)
    compiler = os.environ.get('CC') or shutil.which('cc') or shutil.which('gcc')
    if compiler is None:
        raise RuntimeError('bench host: no C compiler (cc) to build the floor loop; install '
                           'gcc (Debian/Ubuntu: apt-get install gcc)')
    directory.mkdir(parents=True, exist_ok=True)
    with tempfile.NamedTemporaryFile(dir=directory, delete=False) as tmp:
        pass
    try:
        done = subprocess.run([compiler, '-O2', '-o', tmp.name, str(FLOOR_SOURCE)],
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise RuntimeError(f'bench host: building {FLOOR_SOURCE.name} with {compiler} '
                               f'failed:\n{done.stderr}')
        os.chmod(tmp.name, 0o755)
        os.replace(tmp.name, binary)
    finally:
        if os.path.exists(tmp.name):
            os.unlink(tmp.name)
    return str(binary)


def paced_floor(seconds: float, *, period_ns: int = STEP_NS, priority: int = FLOOR_PRIORITY,
                work_ns: int = 0) -> Dict[str, object]:
    """Run the paced floor loop for ``seconds``; return its figures.

    :param seconds: length of the window [s].
    :param period_ns: step period [ns].
    :param priority: SCHED_FIFO priority (0: normal scheduling).
    :param work_ns: computation per step, calibrated to take this long at the median [ns]
        (0: none, the floor).
    :return: ``steps``, ``overruns``, ``max_lateness_ns``, ``late_wakes``, ``policy``,
        ``work_ns`` (as calibrated), ``slow_work`` (steps whose work took over 1.5 times that),
        ``duration_s``, ``steal_percent`` (CPU the hypervisor gave to others meanwhile).
    :raises RuntimeError: if the loop cannot be built or fails.
    """
    program = floor_program()
    before = cpu_times()
    done = subprocess.run([program, repr(float(seconds)), str(int(period_ns)), str(priority),
                           str(int(work_ns))], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f'bench host: the floor loop failed: {done.stderr.strip()}')
    result = json.loads(done.stdout)
    result['duration_s'] = float(seconds)
    result['steal_percent'] = steal_percent(before, cpu_times())
    return result


def _main_paced(args: argparse.Namespace) -> int:
    works = [int(round(ms * 1e6)) for ms in args.work_ms]
    seconds = args.duration / args.windows
    # the windows of every amount of work interleave: window 1 of each, then window 2, ...
    windows = [dict(paced_floor(seconds, work_ns=w), work_requested_ns=w)
               for _ in range(args.windows) for w in works]
    result: Dict[str, object] = {'loop': 'paced', 'duration_s': args.duration,
                                 'policy': windows[0]['policy'], 'windows': windows,
                                 'overruns': {f'{ms:g} ms': sum(
                                     int(w['overruns']) for w in windows
                                     if w['work_requested_ns'] == v)
                                     for ms, v in zip(args.work_ms, works)},
                                 'load_average': os.getloadavg()[0]}
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"paced 1 kHz floor loop ({windows[0]['policy']}, CPU wake-up latency request "
          f"{windows[0].get('latency_request')}), {args.windows} windows of {seconds:g} s per "
          f"amount of work; load {result['load_average']:.2f}")
    for ms, v in zip(args.work_ms, works):
        mine = [w for w in windows if w['work_requested_ns'] == v]
        overruns = [int(w['overruns']) for w in mine]
        print(f"  work {ms:g} ms per step (calibrated {int(mine[0]['work_ns']) * 1e-6:.3f} ms):")
        for w in mine:
            print(f"    overruns {w['overruns']:>5} of {w['steps']} steps, max lateness "
                  f"{w['max_lateness_ns'] * 1e-6:.3f} ms, late wake-ups {w['late_wakes']}, "
                  f"work over 1.5x {w['slow_work']}, CPU stolen by the hypervisor "
                  f"{w['steal_percent']} %")
        print(f'    overruns in total: {sum(overruns)} (median per window '
              f'{float(np.median(overruns)):g})'
              + ('; no 1 kHz loop here can do better' if v == 0 else ''))
    return 0


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin bench host``."""
    p = argparse.ArgumentParser(prog='conveyor-twin bench host', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--loop', choices=('paced', 'busy'), default='paced',
                   help='paced: the floor loop (default); busy: read the clock, never sleep')
    p.add_argument('--duration', type=float, default=30.0, help='seconds of measuring')
    p.add_argument('--windows', type=int, default=1, help='paced: split into this many windows')
    p.add_argument('--work-ms', type=float, nargs='+', default=[0.0],
                   help='paced: computation per step [ms], one loop per value, their windows '
                        'interleaved (0: none, the floor)')
    p.add_argument('--fifo', action='store_true', help='busy: run the loop under SCHED_FIFO 10')
    p.add_argument('--json', action='store_true', help='print one JSON object')
    args = p.parse_args(argv)
    bad = [ms for ms in args.work_ms if not 0.0 <= ms < STEP_NS * 1e-6]
    if bad:
        p.error(f'--work-ms: got {bad[0]:g}; expected 0 <= ms < {STEP_NS * 1e-6:g}')
    if args.loop == 'paced':
        try:
            return _main_paced(args)
        except RuntimeError as exc:
            print(exc, file=sys.stderr)
            return 1
    policy = 'normal'
    if args.fifo:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
            policy = 'SCHED_FIFO 10'
        except (PermissionError, AttributeError, OSError):
            policy = 'normal (SCHED_FIFO refused)'
    before = cpu_times()
    gaps = clock_gaps(args.duration)
    result = {'duration_s': args.duration, 'policy': policy,
              'steal_percent': steal_percent(before, cpu_times()),
              'load_average': os.getloadavg()[0], 'gaps': classify(gaps),
              'longest_gap_ms': round(float(gaps.max()) * 1e-6, 3) if gaps.size else 0.0}
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"clock read in a loop for {args.duration:g} s ({policy}); CPU stolen by the "
          f"hypervisor {result['steal_percent']} %, load {result['load_average']:.2f}")
    for name, count in result['gaps'].items():
        if name != 'over_1ms':
            print(f'  gaps {name:>10}: {count}')
    print(f"  gaps over 1 ms: {result['gaps']['over_1ms']} (each one a late step for any 1 kHz "
          f"loop); longest {result['longest_gap_ms']} ms")
    return 0
