"""The stepping loop for anything steppable: a gate that holds steps back until input arrives
(waits are no overruns, realtime deadlines start again after one), steps in chunks with their
mean per step, listeners after each step, failures reported under the runner's name."""

import threading
import time
from typing import List

import pytest

from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import Health
from conveyor_twin.testing.ros_env import wait_for

WAIT = 60.0  # s, a bound for a loaded machine, not a speed requirement


class Counter:
    """A steppable that counts its steps and checks them against a limit."""

    def __init__(self, limit: int = 1 << 62) -> None:
        self.dt_ns = 1_000_000
        self.health = Health(printer=lambda text: None)
        self.index = 0
        self.calls: List[int] = []
        self.limit = limit
        self.fail_at = 0

    def step(self, n: int = 1) -> None:
        if self.index + n > self.limit:
            raise AssertionError(f'step {self.index + n} beyond the limit {self.limit}')
        if self.fail_at and self.index + n >= self.fail_at:
            raise RuntimeError('injected')
        self.index += n
        self.calls.append(n)


class Gate:
    """Lets the counter step up to ``limit``; the test raises the limit, as new input does."""

    def __init__(self, counter: Counter) -> None:
        self.counter = counter
        self.lock = threading.Lock()
        self.wake = threading.Event()
        self.blocked_at: List[int] = []
        self.first_blocked_ns = 0

    def may_step(self) -> bool:
        return self.counter.index + 1 <= self.counter.limit

    def blocked(self) -> None:
        self.first_blocked_ns = self.first_blocked_ns or time.monotonic_ns()
        if not self.blocked_at or self.blocked_at[-1] != self.counter.index:
            self.blocked_at.append(self.counter.index)

    def allow(self, limit: int) -> None:
        with self.lock:
            self.counter.limit = limit
        self.wake.set()


def run_in_thread(runner: Runner) -> threading.Thread:
    thread = threading.Thread(target=runner.run, daemon=True)
    thread.start()
    return thread


@pytest.mark.parametrize('mode', [TimeMode.FAST, TimeMode.LOCKSTEP, TimeMode.REALTIME])
def test_a_gated_runner_steps_only_as_far_as_the_gate_allows(mode):
    counter = Counter(limit=5)
    gate = Gate(counter)
    after: List[int] = []
    runner = Runner(counter, mode, max_steps=12, gate=gate)
    runner.tuned = False  # no priority or heap freeze for the test process
    runner.listeners.append(lambda: after.append(counter.index))
    thread = run_in_thread(runner)
    assert wait_for(lambda: gate.blocked_at == [5], WAIT)
    gate.allow(9)
    assert wait_for(lambda: gate.blocked_at == [5, 9], WAIT)
    gate.allow(100)
    thread.join(WAIT)
    assert not thread.is_alive() and runner.error is None
    assert counter.index == runner.steps_done == 12 and counter.calls == [1] * 12
    assert after == list(range(1, 13)) and runner.stats.count == 12


def test_a_gated_wait_restarts_the_realtime_deadlines():
    counter = Counter(limit=3)
    gate = Gate(counter)
    runner = Runner(counter, TimeMode.REALTIME, max_steps=6, gate=gate)
    runner.tuned = False
    thread = run_in_thread(runner)
    assert wait_for(lambda: gate.blocked_at == [3], WAIT)
    gate.allow(6)
    thread.join(WAIT)
    assert not thread.is_alive() and counter.index == 6
    # the last three steps' deadlines count from after the wait (which is thus no overrun),
    # not from the start of the run
    assert runner.pacer.start_ns > gate.first_blocked_ns and runner.pacer.index == 3


def test_stop_ends_a_wait_at_a_closed_gate():
    counter = Counter(limit=2)
    gate = Gate(counter)
    runner = Runner(counter, TimeMode.FAST, gate=gate)
    thread = run_in_thread(runner)
    assert wait_for(lambda: gate.blocked_at == [2], WAIT)
    runner.request_stop()
    gate.wake.set()
    thread.join(WAIT)
    assert not thread.is_alive() and counter.index == 2 and runner.error is None


def test_fast_mode_steps_in_chunks_up_to_max_steps():
    counter = Counter()
    reports: List[int] = []
    runner = Runner(counter, TimeMode.FAST, max_steps=10, chunk=4)
    runner.listeners.append(lambda: reports.append(counter.index))
    runner.start()
    assert runner.wait(WAIT) and runner.error is None
    assert counter.calls == [4, 4, 2] and reports == [4, 8, 10]
    assert runner.steps_done == 10 and runner.stats.count == 3


def test_a_chunk_with_a_gate_is_refused():
    counter = Counter()
    with pytest.raises(ValueError, match='chunk 4'):
        Runner(counter, TimeMode.FAST, gate=Gate(counter), chunk=4)


@pytest.mark.parametrize('gated', [False, True])
def test_a_failing_step_is_reported_under_the_runners_name(gated):
    counter = Counter()
    counter.fail_at = 7
    errors: List[BaseException] = []
    runner = Runner(counter, TimeMode.FAST, max_steps=100, on_error=errors.append,
                    gate=Gate(counter) if gated else None, name='cell stepping thread')
    runner.start()
    assert runner.wait(WAIT)
    assert [f.name for f in counter.health.failures] == ['cell stepping thread']
    assert errors == [runner.error] and isinstance(runner.error, RuntimeError)
    assert runner.steps_done == counter.index == 6
