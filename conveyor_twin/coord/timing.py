"""Real-time pacing on absolute deadlines, and step-time statistics."""

from enum import Enum
import time
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.coord.latency import sleep_holding_gil, WakeLatencyRequest

#: The pacer sleeps releasing the interpreter lock until this long before a deadline, then
#: sleeps the rest holding it [ns]: getting the lock back may take another thread's switch
#: interval (0.2 ms in realtime), and at the deadline the step must find it in hand.
APPROACH_NS = 300_000


class TimeMode(str, Enum):
    """How simulation time advances."""

    REALTIME = 'realtime'  # paced by the wall clock on absolute deadlines
    FAST = 'fast'          # as fast as possible
    LOCKSTEP = 'lockstep'  # only when asked (the ``step`` service)


class DeadlinePacer:
    """Sleep until absolute deadlines ``t0 + k * period`` so there is no drift.

    A step whose work ends after its deadline is an overrun; the pacer never skips steps to
    catch up (it runs late steps back to back), so overruns are counted, never hidden.

    Between steps the pacer sleeps with the interpreter lock released (other threads publish,
    record, serve) until :data:`APPROACH_NS` before the deadline, then sleeps the rest holding
    the lock, so the step starts at its deadline with the lock in hand. A realtime loop asks
    for :attr:`latency_request` (zero CPU wake-up latency, opt-in:
    :class:`~conveyor_twin.coord.latency.WakeLatencyRequest`) while it paces, until
    :meth:`close`.

    After each sleep the pacer notes how long after the deadline the thread resumed (its wake
    lateness: the system's wake-up, or another thread holding the interpreter lock); a step
    that fits its period can still end late when it starts late. :meth:`take_latest_wake`
    returns the latest since the last call (the diagnostics' window).

    :param period_ns: step period [ns].
    """

    def __init__(self, period_ns: int) -> None:
        self.period_ns = period_ns
        self.start_ns = time.monotonic_ns()
        self.index = 0
        self.overruns = 0
        self.max_lateness_ns = 0
        self.latest_wake_ns = 0  # latest wake lateness since take_latest_wake [ns]
        self.latency_request = WakeLatencyRequest()

    def restart(self) -> None:
        """Start a new series of deadlines from now."""
        self.start_ns = time.monotonic_ns()
        self.index = 0

    def close(self) -> None:
        """Withdraw the wake-up latency request (pacing again needs :meth:`restart`)."""
        self.latency_request.release()

    def wait_next(self) -> None:
        """Count an overrun if the current step ended late, then sleep to the next deadline."""
        self.index += 1
        deadline = self.start_ns + self.index * self.period_ns
        now = time.monotonic_ns()
        if now > deadline:
            self.overruns += 1
            self.max_lateness_ns = max(self.max_lateness_ns, now - deadline)
            return
        if deadline - now > APPROACH_NS + 50_000:
            time.sleep((deadline - now - APPROACH_NS) * 1e-9)
        sleep_holding_gil(deadline)
        late = time.monotonic_ns() - deadline
        if late > self.latest_wake_ns:
            self.latest_wake_ns = late

    def take_latest_wake(self) -> float:
        """Return the latest wake lateness since the last call [ms], and start anew."""
        late, self.latest_wake_ns = self.latest_wake_ns, 0
        return late * 1e-6


_HIST_BIN_S = 1e-6   # whole-run histogram: 1 us bins up to 100 ms (longer steps: last bin)
_HIST_BINS = 100_000


class StepStats:
    """Step durations [s] in a window (for 1 Hz diagnostics) and over the whole run.

    The whole-run figures come from a fixed 1 us histogram, so memory stays constant however
    long the run; the mean and the maximum are exact.
    """

    def __init__(self, window: int = 1000) -> None:
        self._window = np.zeros(window, dtype=np.float64)
        self._count = 0
        self._hist = np.zeros(_HIST_BINS, dtype=np.int64)
        self._sum = 0.0
        self._max = 0.0

    def add(self, seconds: float) -> None:
        """Record one step's duration [s]."""
        self._window[self._count % self._window.size] = seconds
        self._count += 1
        self._hist[min(int(seconds / _HIST_BIN_S), _HIST_BINS - 1)] += 1
        self._sum += seconds
        self._max = max(self._max, seconds)

    @staticmethod
    def _summary(values: np.ndarray) -> Dict[str, float]:
        """Mean, median, p99 (linear interpolation, as ``np.percentile``) and max [ms].

        One partial sort for the three order statistics: the diagnostics call this on the
        stepping thread, where ``np.median`` and ``np.percentile`` cost ~0.3 ms with cold
        caches.
        """
        n = values.size
        if n == 0:
            return {'mean_ms': 0.0, 'p50_ms': 0.0, 'p99_ms': 0.0, 'max_ms': 0.0}
        ranks = {}
        for q in (0.5, 0.99):
            lo = int(q * (n - 1))
            ranks[q] = (lo, min(lo + 1, n - 1), q * (n - 1) - lo)
        ordered = np.partition(values, sorted({r for lo, hi, _ in ranks.values()
                                               for r in (lo, hi)} | {n - 1}))

        def rank(q: float) -> float:
            lo, hi, frac = ranks[q]
            a, b = float(ordered[lo]), float(ordered[hi])
            return (a + (b - a) * frac) * 1e3

        return {'mean_ms': float(values.mean()) * 1e3, 'p50_ms': rank(0.5),
                'p99_ms': rank(0.99), 'max_ms': float(ordered[n - 1]) * 1e3}

    def window(self) -> Dict[str, float]:
        """Mean, median, p99 and max [ms] over the last window of steps."""
        return self._summary(self._window[:min(self._count, self._window.size)])

    def total(self) -> Dict[str, float]:
        """Mean, median, p99 and max [ms] over every step recorded (percentiles to 1 us)."""
        if not self._count:
            return self._summary(self._window[:0])
        cumulative = np.cumsum(self._hist)

        def percentile(q: float) -> float:
            index = int(np.searchsorted(cumulative, q * self._count))
            return (index + 0.5) * _HIST_BIN_S * 1e3

        return {'mean_ms': self._sum / self._count * 1e3, 'p50_ms': percentile(0.5),
                'p99_ms': percentile(0.99), 'max_ms': self._max * 1e3}

    @property
    def count(self) -> int:
        """Number of steps recorded."""
        return self._count


class StepParts:
    """Where the slowest recent step went: its wall time in each part of the step and its CPU
    time [ms].

    The twin hands :meth:`add` every step's wall time per part [ns] (``labels``: its commands
    and actuation, each stage, its outputs) and the stepping thread's CPU time in it; a late
    step shows which part made it late, and whether the step worked that long (CPU time near
    the wall time) or waited for the CPU (the machine ran something else). Kept per block of
    ``window`` steps: :meth:`slowest` is the slowest step of the current block and the block
    before, so a reader at any rate sees the slowest of the last one or two windows.

    :param labels: the parts' names, in the order :meth:`add` gets them.
    :param window: steps per block (1000: one second at 1 kHz, as :class:`StepStats`).
    """

    def __init__(self, labels: Sequence[str], window: int = 1000) -> None:
        self.labels = list(labels)
        self._window = window
        self._count = 0
        self._current: Optional[Tuple[List[int], int]] = None
        self._current_total = -1
        self._before: Optional[Tuple[List[int], int]] = None
        self._before_total = -1

    def add(self, laps_ns: List[int], cpu_ns: int) -> None:
        """Record one step's wall time per part and its CPU time [ns] (the parts are copied if
        it is the slowest so far)."""
        total = sum(laps_ns)
        if total > self._current_total:
            self._current_total = total
            self._current = (list(laps_ns), cpu_ns)
        self._count += 1
        if self._count >= self._window:
            self._before, self._before_total = self._current, self._current_total
            self._current, self._current_total, self._count = None, -1, 0

    def slowest(self) -> Optional[Dict[str, float]]:
        """Return the slowest recent step's wall time per part, its ``total`` and its ``cpu``
        time [ms] (None before the first step)."""
        record = self._current if self._current_total >= self._before_total else self._before
        if record is None:
            return None
        laps, cpu_ns = record
        parts = {label: ns * 1e-6 for label, ns in zip(self.labels, laps)}
        parts['total'] = sum(laps) * 1e-6
        parts['cpu'] = cpu_ns * 1e-6
        return parts

    def describe(self) -> str:
        """Return the parts of :meth:`slowest` as one line, the largest first: ``micro 0.712,
        outputs 0.061, ...`` [ms] ('' before the first step)."""
        parts = self.slowest()
        if parts is None:
            return ''
        del parts['total'], parts['cpu']
        return ', '.join(f'{label} {ms:.3f}' for label, ms in
                         sorted(parts.items(), key=lambda item: -item[1]))
