"""Pausing the stepping thread: the clock holds, steps on request while paused, and a resumed
realtime runner starts new deadlines (the pause is no overrun, no catch-up burst follows)."""

import time

import pytest

from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.testing.ros_env import wait_for

from test.coord.test_runner import Counter, WAIT


@pytest.mark.parametrize('mode', [TimeMode.FAST, TimeMode.REALTIME])
def test_a_paused_runner_holds_its_clock_steps_on_request_and_resumes(mode):
    counter = Counter()
    runner = Runner(counter, mode)
    runner.tuned = False  # no priority or heap freeze for the test process
    runner.start()
    try:
        assert wait_for(lambda: counter.index >= 3, WAIT)
        assert runner.pause() and runner.paused and runner.running
        assert not runner.pause()  # already paused
        held = counter.index
        assert runner.steps_done == held  # the thread ended after a whole step
        paused_ns = time.monotonic_ns()
        overruns = runner.overruns
        runner.step(4)
        assert counter.index == held + 4 == runner.steps_done
        assert runner.resume() and not runner.paused and not runner.resume()
        assert wait_for(lambda: counter.index >= held + 8, WAIT)
    finally:
        runner.stop()
    assert runner.error is None and not runner.running
    if mode is TimeMode.REALTIME:
        # deadlines count from the resume, not from the start: the pause is no overrun and
        # no steps run back to back to catch up with it
        assert runner.pacer.start_ns > paused_ns
        assert runner.overruns - overruns <= runner.pacer.index


def test_pause_of_a_lockstep_or_stopped_runner_does_nothing():
    counter = Counter()
    lockstep = Runner(counter, TimeMode.LOCKSTEP)
    lockstep.start()
    assert not lockstep.pause() and not lockstep.paused and not lockstep.resume()
    fast = Runner(counter, TimeMode.FAST, max_steps=5)
    fast.start()
    assert fast.wait(WAIT)
    assert not fast.pause() and not fast.running


def test_stop_of_a_paused_runner_ends_it():
    counter = Counter()
    runner = Runner(counter, TimeMode.FAST)
    runner.start()
    assert wait_for(lambda: counter.index >= 1, WAIT)
    assert runner.pause()
    runner.stop()
    assert not runner.running and not runner.paused and not runner.resume()


def test_the_real_time_factor_holds_while_paused():
    counter = Counter()
    runner = Runner(counter, TimeMode.FAST)
    runner.start()
    assert wait_for(lambda: counter.index >= 3, WAIT)
    runner.pause()
    factor = runner.real_time_factor()
    assert wait_for(lambda: time.monotonic() > runner.wall_end, WAIT)
    assert runner.real_time_factor() == factor > 0.0  # the pause's wall time does not count
    held = counter.index
    runner.resume()
    assert wait_for(lambda: counter.index >= held + 3, WAIT)
    runner.stop()
