"""Checks of the numeric arguments of the public testing API.

Each raises a :class:`ValueError` that names the argument, the value given and what is allowed,
before anything is sent to the twin (a bool, a string or NaN is never taken for a number).
"""

import math
import numbers
from typing import Any, Optional, Sequence, List

UINT32_MAX = 2**32 - 1
UINT64_MAX = 2**64 - 1


def _is_integer(value: Any) -> bool:
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def integer(name: str, value: Any, low: int, high: Optional[int] = None) -> int:
    """Return ``value`` as an int if it is an integer in ``[low, high]`` (no upper bound when
    ``high`` is None); else raise ValueError naming ``name``, the value and the range."""
    allowed = f'an integer in [{low}, {high}]' if high is not None else f'an integer >= {low}'
    if not _is_integer(value) or value < low or (high is not None and value > high):
        raise ValueError(f'{name} = {value!r} is not allowed: it must be {allowed}')
    return int(value)


def number(name: str, value: Any) -> float:
    """Return ``value`` as a float if it is a real number (NaN and infinities pass: the twin
    judges the value, e.g. rejects a non-finite command); else raise ValueError."""
    if not _is_number(value):
        raise ValueError(f'{name} = {value!r} is not allowed: it must be a real number '
                         '(int or float)')
    return float(value)


def seconds(name: str, value: Any, *, low: float = 0.0, open_low: bool = False,
            optional: bool = False) -> Optional[float]:
    """Return a finite duration [s] >= ``low`` (> ``low`` with ``open_low``); None passes
    with ``optional``; else raise ValueError naming the argument, value and range."""
    if value is None and optional:
        return None
    bracket = '(' if open_low else '['
    allowed = f'a finite number of seconds in {bracket}{low:g}, inf)'
    if optional:
        allowed += ' or None'
    if not _is_number(value) or not math.isfinite(value) \
            or (value <= low if open_low else value < low):
        raise ValueError(f'{name} = {value!r} is not allowed: it must be {allowed}')
    return float(value)


def numbers_of(name: str, values: Any) -> List[float]:
    """Return a sequence (or one number) of real numbers as floats; else raise ValueError
    naming the argument and the first bad entry."""
    if _is_number(values):
        return [float(values)]
    try:
        items: Sequence[Any] = list(values)
    except TypeError:
        raise ValueError(f'{name} = {values!r} is not allowed: it must be a number or a '
                         'sequence of numbers') from None
    for i, v in enumerate(items):
        if not _is_number(v):
            raise ValueError(f'{name}[{i}] = {v!r} is not allowed: it must be a real number')
    return [float(v) for v in items]
