"""Simulation time as exact integers: step index <-> nanoseconds."""

from typing import Tuple

NS_PER_S = 1_000_000_000


def step_ns(step_s: float) -> int:
    """Return the step length in integer nanoseconds; it must be a whole number of ns.

    :param step_s: step length [s].
    :raises ValueError: if the step is not a positive whole number of nanoseconds.
    """
    ns = round(step_s * NS_PER_S)
    if ns <= 0 or abs(ns - step_s * NS_PER_S) > 1e-6:
        raise ValueError(f'step {step_s!r} s is not a positive whole number of nanoseconds')
    return ns


def stamp(time_ns: int) -> Tuple[int, int]:
    """Split a time [ns] into (sec, nanosec) as in builtin_interfaces/Time."""
    return time_ns // NS_PER_S, time_ns % NS_PER_S
