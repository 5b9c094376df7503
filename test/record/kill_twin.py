"""Child process of ``test_run_kill``: ``conveyor-twin run ARGS`` with a step probe.

``python kill_twin.py PROBE_FILE RUN_ARGS...`` runs ``conveyor-twin run RUN_ARGS`` unchanged,
except that a last step listener writes, after every step's messages went to the recorder,
the step index and the monotonic time [ns] into the shared file ``PROBE_FILE`` (int64: [0] the
last step done, [1 + step % RING] the time it was done). The writes survive SIGKILL (shared
mapping), so the test knows which steps were handed to the recorder before the kill and when.
"""

import sys
import time

import numpy as np

RING = 4096


def main() -> int:
    import faulthandler
    import signal
    faulthandler.register(signal.SIGUSR1, all_threads=True)  # the test's view of a hang
    probe_path, argv = sys.argv[1], sys.argv[2:]
    probe = np.memmap(probe_path, dtype='<i8', mode='r+', shape=(RING + 1,))
    from conveyor_twin.ros import run_recording
    start = run_recording.start_recording

    def start_recording(composed, *args, **kwargs):
        recording = start(composed, *args, **kwargs)

        def on_step(inp, _commands):
            probe[1 + inp.step % RING] = time.monotonic_ns()
            probe[0] = inp.step

        composed.twin.step_listeners.append(on_step)
        return recording

    run_recording.start_recording = start_recording
    from conveyor_twin.cli import run
    return run.main(argv)


if __name__ == '__main__':
    sys.exit(main())
