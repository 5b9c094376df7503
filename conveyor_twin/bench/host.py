"""``conveyor-twin bench host``: can this machine give a thread every millisecond?

A thread that does nothing but read the monotonic clock in a loop should see the clock advance
by well under a microsecond per iteration. Every larger jump is time the thread did not run:
the kernel ran something else, or (on a virtual machine) the hypervisor gave the CPU to another
guest (``steal``). No 1 kHz loop on the machine can be on time through such a gap, whatever it
computes, so the count of gaps over 1 ms bounds the overruns any real-time twin can reach here.
``--fifo`` runs the loop under SCHED_FIFO, as the twin's stepping thread does (where allowed;
note that Linux throttles real-time threads that never sleep: by default to 95 % of each
second, which shows up as one ~50 ms gap per second).
"""

import argparse
import json
import os
import time
from typing import Dict, List

import numpy as np

from conveyor_twin.bench.twin import cpu_times, steal_percent

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


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin bench host``."""
    p = argparse.ArgumentParser(prog='conveyor-twin bench host', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--duration', type=float, default=30.0, help='seconds of clock reading')
    p.add_argument('--fifo', action='store_true', help='run the loop under SCHED_FIFO 10')
    p.add_argument('--json', action='store_true', help='print one JSON object')
    args = p.parse_args(argv)
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
