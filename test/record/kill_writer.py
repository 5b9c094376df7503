"""Child process for the kill test: record a paced 1 kHz run until killed.

Usage: python kill_writer.py <path> <flush_period_s>. Prints the step index after each step's
messages have been handed to the recorder.
"""

import sys
import time

import numpy as np

from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.wire import cdr

DT_NS = 1_000_000


def main() -> None:
    path, flush_period = sys.argv[1], float(sys.argv[2])
    n = 50
    rng = np.random.default_rng(0)
    arrays = [rng.random(n) for _ in range(6)]
    ids = np.arange(1, n + 1, dtype=np.uint32)
    types = np.zeros(n, dtype=np.uint16)
    rec = McapRecorder(path, flush_period=flush_period, chunk_size=64 << 20, seed=1,
                       step_ns=DT_NS, cell_yaml='cell:\n  name: kill_test\n')
    rec.add_topic('/parts', 'conveyor_twin_msgs/msg/PartStates')
    rec.add_topic('/clock', 'rosgraph_msgs/msg/Clock')
    start = time.monotonic()
    step = 0
    while True:
        t = step * DT_NS
        rec.record('/parts', t, cdr.encode_part_states(t, 'cell', step, ids, types, *arrays))
        rec.record('/clock', t, cdr.encode_clock(t))
        sys.stdout.write(f'{step}\n')
        sys.stdout.flush()
        step += 1
        delay = start + step * 1e-3 - time.monotonic()
        if delay > 0:
            time.sleep(delay)


if __name__ == '__main__':
    main()
