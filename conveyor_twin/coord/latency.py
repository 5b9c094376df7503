"""What a 1 kHz loop asks of the operating system: short wake-ups, and the interpreter lock in
hand at its deadline.

- :class:`WakeLatencyRequest` holds a PM QoS request for zero CPU wake-up latency
  (``/dev/cpu_dma_latency``, as ``cyclictest`` does) while a realtime loop runs, when asked
  for with :data:`LATENCY_ENV` ``=1``: idle CPUs then poll instead of halting, so a sleeping
  loop wakes within microseconds. It is off by default: on a virtual machine the polling CPUs
  look busy to the hypervisor, which then preempts them more (docs/benchmarks.md, "Where late
  steps come from"). It needs write access to the device (root or a udev rule); without it the
  loop runs as before and the request reports why.
- :func:`sleep_holding_gil` sleeps to an absolute deadline *without* releasing Python's
  interpreter lock, so no other thread of the process can take it in the last few hundred
  microseconds before a step: the step starts at its deadline instead of after another thread's
  switch interval.
"""

import ctypes
import ctypes.util
import os
import struct
import time
from typing import Callable, Optional

#: Device of the kernel's CPU wake-up latency request (PM QoS) [us, int32].
CPU_LATENCY_DEVICE = '/dev/cpu_dma_latency'
#: Set to ``1`` to hold the zero wake-up latency request while the twin runs in realtime.
LATENCY_ENV = 'CONVEYOR_TWIN_CPU_LATENCY_REQUEST'
_CLOCK_MONOTONIC = 1
_TIMER_ABSTIME = 1


class _Timespec(ctypes.Structure):
    _fields_ = [('tv_sec', ctypes.c_long), ('tv_nsec', ctypes.c_long)]


class WakeLatencyRequest:
    """A held request for zero CPU wake-up latency; released by :meth:`release` (or at exit).

    :ivar status: ``held``, ``off`` (disabled by :data:`LATENCY_ENV`) or why it was refused.
    """

    def __init__(self) -> None:
        self._fd: Optional[int] = None
        self.status = 'not requested'

    @property
    def held(self) -> bool:
        """True while the request is in force."""
        return self._fd is not None

    def acquire(self) -> bool:
        """Ask for zero wake-up latency; return True if the request is held."""
        if self._fd is not None:
            return True
        if os.environ.get(LATENCY_ENV, '0').strip() != '1':
            self.status = f'off (set {LATENCY_ENV}=1 to request it)'
            return False
        try:
            fd = os.open(CPU_LATENCY_DEVICE, os.O_WRONLY)
        except OSError as exc:
            self.status = f'refused: {CPU_LATENCY_DEVICE}: {exc.strerror}'
            return False
        try:
            os.write(fd, struct.pack('i', 0))
        except OSError as exc:
            os.close(fd)
            self.status = f'refused: {CPU_LATENCY_DEVICE}: {exc.strerror}'
            return False
        self._fd = fd
        self.status = 'held'
        return True

    def release(self) -> None:
        """Withdraw the request (the kernel drops it when the device is closed)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
            self.status = 'released'

    def __del__(self) -> None:
        self.release()


def _gil_holding_sleeper() -> Optional[Callable[[int], None]]:
    """Return a function that sleeps to an absolute monotonic time [ns] holding the GIL, or
    None where ``clock_nanosleep`` is not available."""
    name = ctypes.util.find_library('c')
    try:
        libc = ctypes.PyDLL(name)  # PyDLL: calls keep the interpreter lock
        nanosleep = libc.clock_nanosleep
    except (OSError, AttributeError, TypeError):
        return None
    nanosleep.argtypes = (ctypes.c_int, ctypes.c_int, ctypes.POINTER(_Timespec), ctypes.c_void_p)
    nanosleep.restype = ctypes.c_int
    spec = _Timespec()
    ref = ctypes.byref(spec)

    def sleep_until(deadline_ns: int) -> None:
        spec.tv_sec, spec.tv_nsec = divmod(deadline_ns, 1_000_000_000)
        nanosleep(_CLOCK_MONOTONIC, _TIMER_ABSTIME, ref, None)

    # time.monotonic_ns reads CLOCK_MONOTONIC on Linux, the clock the sleep above uses
    return sleep_until if os.uname().sysname == 'Linux' else None


_SLEEPER = _gil_holding_sleeper()


def sleep_holding_gil(deadline_ns: int) -> None:
    """Sleep until the monotonic clock reads ``deadline_ns`` [ns], keeping the interpreter
    lock; spin where the system sleep is not available. May return early on a signal: the
    caller spins the rest."""
    if _SLEEPER is not None:
        _SLEEPER(deadline_ns)
    while time.monotonic_ns() < deadline_ns:
        pass
