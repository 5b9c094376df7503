"""The stepping thread: realtime on absolute deadlines, or as fast as possible.

One loop for everything that steps: a cell's :class:`~conveyor_twin.coord.twin.Twin` (any
layout) and a plant's cells. :class:`Runner` steps a :class:`Steppable`, optionally behind a
:class:`StepGate` that says whether the next step may run now (a plant cell's conservative
synchronisation, :mod:`conveyor_twin.plant.sync`): while it says no, the runner sleeps on the
gate's ``wake`` event and restarts its realtime deadlines afterwards, so a wait for input is
never an overrun.

Lockstep needs no thread: whoever asks (the ``step`` service, a test) calls :meth:`Runner.step`.
Every step's duration (the twin's step and everything its listeners do, e.g. publishing) is
recorded in :attr:`Runner.stats`; in realtime a step that ends after its deadline is an overrun.
"""

import gc
import os
import sys
import threading
import time
from typing import Callable, ContextManager, Iterable, List, Optional, Protocol, Set

from conveyor_twin.coord.timing import DeadlinePacer, StepStats, TimeMode
from conveyor_twin.health import Health

# GIL switch interval while a realtime loop runs [s]: Python's 5 ms default lets another thread
# (the ROS executor serving a service or a command) hold the GIL for up to 5 steps.
REALTIME_SWITCH_INTERVAL = 2e-4
# SCHED_FIFO priority of the realtime stepping thread (1-99; 0 or no permission: normal
# scheduling). Other processes on a loaded machine then cannot stall a step for tens of ms;
# the kernel's RT throttling (95 % by default) keeps the machine usable. Override with the
# environment variable below.
REALTIME_PRIORITY = 10
PRIORITY_ENV = 'CONVEYOR_TWIN_RT_PRIORITY'
#: Name under which a failed step of the stepping thread is reported to the twin's health.
STEPPING_THREAD = 'stepping thread'
#: Longest sleep on a closed gate's ``wake`` event before the runner asks it again [s].
GATE_WAIT = 0.05


def realtime_priority(helper: bool = False) -> int:
    """Return the SCHED_FIFO priority for the stepping thread, or for a helper thread (one
    below: the executor and markers threads, so that other processes cannot preempt them while
    they hold the GIL the stepping thread waits for)."""
    priority = int(os.environ.get(PRIORITY_ENV, REALTIME_PRIORITY))
    return max(priority - 1, 0) if helper else priority


def freeze_heap() -> None:
    """Collect garbage once, then exempt every object alive now from later collections.

    A full collection of the twin's heap (rclpy, numba, numpy: ~130,000 objects) takes
    60-80 ms with the GIL held, i.e. 60-80 late steps whenever Python decides to run one;
    after ``gc.freeze()`` later collections only scan what was allocated since (well under
    1 ms). :func:`thaw_heap` undoes it.
    """
    gc.collect()
    gc.freeze()


def thaw_heap() -> None:
    """Return the frozen objects to the collector (after a realtime run)."""
    gc.unfreeze()


def raise_thread_priority(priority: int) -> int:
    """Put the calling thread under SCHED_FIFO at ``priority``; return it, or 0 if refused."""
    if priority <= 0 or not hasattr(os, 'sched_setscheduler'):
        return 0
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, ValueError):
        return 0
    return priority


def thread_ids() -> Set[int]:
    """Return the ids of this process's threads (empty where ``/proc`` is missing)."""
    try:
        return {int(tid) for tid in os.listdir('/proc/self/task')}
    except OSError:
        return set()


def raise_threads(tids: Iterable[int], priority: int) -> int:
    """Put every thread of ``tids`` that runs under normal scheduling under SCHED_FIFO at
    ``priority``; return how many were raised.

    For the threads a realtime twin starts besides its stepping thread (the middleware's, a
    viewer's): a normally scheduled thread that another process preempts while it holds the
    interpreter lock, or a middleware lock a publish waits for, stalls the step for a
    scheduler time slice; and a step that had to hand the interpreter lock over waits until
    the thread that asked for it gets a CPU. Threads they start later inherit the priority.
    """
    if priority <= 0 or not hasattr(os, 'sched_setscheduler'):
        return 0
    raised = 0
    for tid in tids:
        try:
            if os.sched_getscheduler(tid) == os.SCHED_OTHER:
                os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
                raised += 1
        except OSError:  # the thread ended meanwhile, or no permission
            continue
    return raised


class Steppable(Protocol):
    """What a :class:`Runner` steps: a :class:`~conveyor_twin.coord.twin.Twin`, a plant cell.

    A steppable may also have ``stages``, ``cell`` and ``seed`` (a twin): realtime then loads
    its kernels first (:attr:`Runner.warm_up`).
    """

    #: Step period [ns].
    dt_ns: int
    #: Where the stepping thread reports its failure.
    health: Health

    def step(self, n: int = 1) -> object:
        """Advance ``n`` steps."""


class StepGate(Protocol):
    """Whether a gated :class:`Runner` may run its next step now (e.g. a plant cell may run
    only as far ahead of its neighbours as the link delays allow).

    The runner asks :meth:`may_step` and runs the step with :attr:`lock` held (whoever feeds
    the gate new input takes the lock too, so the answer holds for the step). While the gate
    says no, the runner calls :meth:`blocked`, then sleeps on :attr:`wake` (which the gate's
    owner sets when new input arrives) for at most :data:`GATE_WAIT`, and asks again.
    """

    lock: ContextManager
    wake: threading.Event

    def may_step(self) -> bool:
        """True if the next step may run now."""

    def blocked(self) -> None:
        """Called on the stepping thread before each wait for input (e.g. to send what the
        neighbours need to move on)."""


class Runner:
    """Advance a :class:`Steppable` (a :class:`~conveyor_twin.coord.twin.Twin`) according to a
    :class:`TimeMode`.

    :param twin: what to step.
    :param mode: realtime, fast or lockstep.
    :param max_steps: stop after this many steps (None: until :meth:`stop`).
    :param on_error: called with the exception if a step raises; the thread then stops.
        The exception is first reported to ``twin.health`` as ``name``.
    :param gate: step only when it allows (:class:`StepGate`); None: always.
    :param chunk: fast mode without a gate: steps per call of ``twin.step`` (the statistics
        get each call's mean per step).
    :param name: what a failure of the stepping thread is reported as.

    Attributes to set before :meth:`start`: :attr:`warm_up`, :attr:`tuned`, :attr:`listeners`.
    """

    def __init__(self, twin: Steppable, mode: TimeMode, *, max_steps: Optional[int] = None,
                 on_error: Optional[Callable[[BaseException], None]] = None,
                 gate: Optional[StepGate] = None, chunk: int = 1,
                 name: str = STEPPING_THREAD) -> None:
        if chunk < 1 or (gate is not None and chunk != 1):
            raise ValueError(f'Runner: chunk {chunk}: expected an integer >= 1, and 1 with a '
                             'gate (the gate allows one step at a time)')
        self.twin = twin
        self.mode = TimeMode(mode)
        self.max_steps = max_steps
        self.gate = gate
        self.chunk = chunk
        self.name = name
        self.stats = StepStats()
        self.pacer = DeadlinePacer(twin.dt_ns)
        self.steps_done = 0
        self.error: Optional[BaseException] = None
        self._on_error = on_error
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self.wall_start = 0.0
        self.wall_end = 0.0
        self.priority = 0  # SCHED_FIFO priority the realtime thread got (0: normal)
        self.warm_up = True  # realtime: load the kernels on a scratch twin before starting
        #: Realtime: raise the thread's priority, shorten the GIL switch interval and freeze
        #: the heap while the loop runs.
        self.tuned = True
        #: Called on the stepping thread after each call of ``twin.step``, outside its timing.
        self.listeners: List[Callable[[], None]] = []
        self._paused = False
        self._wall_before = 0.0  # wall time [s] stepped before the last pause

    @property
    def overruns(self) -> int:
        """Realtime steps that ended after their deadline."""
        return self.pacer.overruns

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps now, timing each (lockstep and tests)."""
        for _ in range(n):
            start = time.perf_counter()
            self.twin.step(1)
            self.stats.add(time.perf_counter() - start)
            self.steps_done += 1

    def start(self) -> None:
        """Start the stepping thread (realtime or fast); lockstep does nothing.

        Realtime first loads every per-step kernel on a scratch copy of the cell
        (:func:`~conveyor_twin.coord.warmup.warm_up`), so no step waits for numba.
        """
        if (self.mode is TimeMode.REALTIME and self.warm_up
                and getattr(self.twin, 'stages', None)):
            from conveyor_twin.coord.warmup import warm_up
            warm_up(self.twin.cell, self.twin.seed)
        self.wall_start = time.monotonic()
        if self.mode is TimeMode.LOCKSTEP:
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self.run, name='conveyor_twin_steps',
                                        daemon=True)
        self._thread.start()

    def run(self) -> None:
        """Step in the calling thread until :meth:`stop`, ``max_steps`` or a failure (what
        :meth:`start`'s thread runs; lockstep steps as fast mode does). A failure is reported
        to ``twin.health`` as :attr:`name`, kept in :attr:`error` and given to ``on_error``.
        """
        realtime = self.mode is TimeMode.REALTIME
        tuned = realtime and self.tuned
        switch_interval = sys.getswitchinterval()
        if tuned:
            sys.setswitchinterval(REALTIME_SWITCH_INTERVAL)
            self.priority = raise_thread_priority(realtime_priority())
            freeze_heap()
        if realtime:
            self.pacer.latency_request.acquire()
        self.pacer.restart()  # after a pause too: deadlines from now, no catch-up steps
        # after the set-up above: rtf counts stepping only (not the set-up, not pauses)
        self.wall_start = time.monotonic() - self._wall_before
        try:
            if self.gate is not None:
                self._gated_loop(realtime)
            elif self.chunk == 1 and not self.listeners:
                self._loop(realtime)
            else:
                self._chunked_loop(realtime)
        except BaseException as exc:  # reported, never swallowed silently
            self.error = exc
            self.twin.health.report(self.name, exc)
            if self._on_error is not None:
                self._on_error(exc)
        finally:
            self.wall_end = time.monotonic()
            sys.setswitchinterval(switch_interval)
            self.pacer.close()  # withdraws the wake-up latency request
            if tuned:
                thaw_heap()
            self._stop.set()

    def _loop(self, realtime: bool) -> None:
        """One step at a time, nothing else (a twin: its listeners do the per-step work)."""
        while not self._stop.is_set():
            if self.max_steps is not None and self.steps_done >= self.max_steps:
                break
            self.step(1)
            if realtime:
                self.pacer.wait_next()

    def _gated_loop(self, realtime: bool) -> None:
        """One step at a time as the gate allows, then the listeners."""
        gate, stats, listeners, pacer = self.gate, self.stats, self.listeners, self.pacer
        step, may_step, lock, wake = self.twin.step, gate.may_step, gate.lock, gate.wake
        stopped, clock, max_steps = self._stop.is_set, time.perf_counter, self.max_steps
        while not stopped():
            if max_steps is not None and self.steps_done >= max_steps:
                break
            with lock:
                ready = may_step()
                if ready:
                    start = clock()
                    step(1)
                    stats.add(clock() - start)
                    self.steps_done += 1
            if not ready:
                gate.blocked()
                wake.wait(GATE_WAIT)
                wake.clear()
                if realtime:  # waiting for input is no overrun: new deadlines from now
                    pacer.restart()
                continue
            for listener in listeners:
                listener()
            if realtime:
                pacer.wait_next()

    def _chunked_loop(self, realtime: bool) -> None:
        """``chunk`` steps at a time in fast mode (else one), then the listeners."""
        twin, stats, listeners = self.twin, self.stats, self.listeners
        chunk = self.chunk if self.mode is TimeMode.FAST else 1
        while not self._stop.is_set():
            n = chunk
            if self.max_steps is not None:
                n = min(n, self.max_steps - self.steps_done)
                if n <= 0:
                    break
            start = time.perf_counter()
            twin.step(n)
            stats.add((time.perf_counter() - start) / n)  # mean per step
            self.steps_done += n
            for listener in listeners:
                listener()
            if realtime:
                self.pacer.wait_next()

    @property
    def running(self) -> bool:
        """True while the stepping thread runs, or is paused (:meth:`pause`)."""
        return self._paused or (self._thread is not None and self._thread.is_alive())

    @property
    def paused(self) -> bool:
        """True between :meth:`pause` and :meth:`resume`."""
        return self._paused

    def pause(self) -> bool:
        """Stop the stepping thread after the current step and hold the clock (realtime, fast).

        Nothing is added to the step: the thread ends as at :meth:`stop`, and :meth:`resume`
        starts it again with new realtime deadlines, so the pause is neither an overrun nor
        followed by catch-up steps. While paused, :meth:`step` steps on request.

        :return: True if the thread was stepping and is now paused; False if it was not
            stepping (lockstep, not started, already paused, stopped or at ``max_steps``).
        """
        if self._paused or not (self._thread is not None and self._thread.is_alive()):
            return False
        self._stop.set()
        self._thread.join()
        self._paused = True
        self._wall_before = self.wall_end - self.wall_start
        return True

    def resume(self) -> bool:
        """Start stepping again after :meth:`pause` (no warm-up; new realtime deadlines).

        :return: True if it resumed; False if it was not paused.
        """
        if not self._paused:
            return False
        self._paused = False
        self.wall_end = 0.0
        self._stop.clear()
        self._thread = threading.Thread(target=self.run, name='conveyor_twin_steps',
                                        daemon=True)
        self._thread.start()
        return True

    def wait(self, timeout: Optional[float] = None) -> bool:
        """Wait until the thread has stopped; return True if it has."""
        if self._thread is None:
            return True
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def request_stop(self) -> None:
        """Ask the stepping thread to stop after the current step; do not wait (e.g. from a
        signal handler)."""
        self._stop.set()

    def stop(self) -> None:
        """Stop the stepping thread after the current step (a paused runner stays stopped)."""
        self._paused = False
        self._stop.set()
        self.wait(10.0)
        if not self.wall_end:
            self.wall_end = time.monotonic()

    def real_time_factor(self) -> float:
        """Simulated time over wall time since :meth:`start`."""
        end = self.wall_end if self.wall_end else time.monotonic()
        wall = end - self.wall_start
        return self.steps_done * self.twin.dt_ns * 1e-9 / wall if wall > 0 else 0.0
