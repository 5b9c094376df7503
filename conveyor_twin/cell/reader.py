"""Read the keys of one YAML mapping of a cell description, each checked (type, range), with
errors (:class:`~conveyor_twin.cell.errors.CellError`) naming file, key path, value and what was
expected."""

import math
from typing import Any, List, Optional, Sequence, Tuple, Union

from conveyor_twin.cell.errors import CellError
from conveyor_twin.cell.model import Point, Rect

#: Largest coordinate of a point or rectangle [m]: a cell spans at most 2 km in x and in y.
COORDINATE_LIMIT = 1000.0
_REQUIRED = object()
_INF = math.inf


class KeyReader:
    """Read keys of one YAML mapping, checking each; :meth:`done` rejects keys not read."""

    def __init__(self, file: str, path: str, data: Any) -> None:
        if not isinstance(data, dict):
            raise CellError(file, path or '<top level>', data, 'a mapping of keys to values')
        self.file = file
        self.path = path
        self.data = data
        self.seen: set = set()

    def key_path(self, key: Union[str, int]) -> str:
        if isinstance(key, int):
            return f'{self.path}[{key}]'
        return f'{self.path}.{key}' if self.path else key

    def fail(self, key: Union[str, int], value: Any, expected: str) -> CellError:
        return CellError(self.file, self.key_path(key), value, expected)

    def raw(self, key: str, default: Any = _REQUIRED) -> Any:
        self.seen.add(key)
        if key not in self.data or self.data[key] is None and default is not _REQUIRED:
            if default is _REQUIRED:
                raise self.fail(key, None, 'this required key to be present')
            return default
        return self.data[key]

    def number(self, key: str, default: Any = _REQUIRED, *, low: float = -_INF,
               high: float = _INF, low_open: bool = False) -> float:
        """Read a finite number in [low, high] (or (low, high] with ``low_open``)."""
        value = self.raw(key, default)
        if value is default and default is not _REQUIRED:
            return default
        return check_number(self, key, value, low, high, low_open)

    def integer(self, key: str, default: Any = _REQUIRED, *, low: int = 0,
                high: int = 2 ** 63 - 1) -> int:
        value = self.raw(key, default)
        if value is default and default is not _REQUIRED:
            return default
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(key, value, f'an integer in [{low}, {high}]')
        if not low <= value <= high:
            raise self.fail(key, value, f'an integer in [{low}, {high}]')
        return value

    def string(self, key: str, default: Any = _REQUIRED,
               choices: Optional[Sequence[str]] = None) -> str:
        value = self.raw(key, default)
        if value is default and default is not _REQUIRED:
            return default
        if not isinstance(value, str) or not value or not value.isprintable():
            raise self.fail(key, value, 'a non-empty string of printable characters')
        if choices is not None and value not in choices:
            raise self.fail(key, value, 'one of ' + ', '.join(repr(c) for c in choices))
        return value

    def boolean(self, key: str, default: Any = _REQUIRED) -> bool:
        """Read ``true`` or ``false``."""
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise self.fail(key, value, 'true or false')
        return value

    def point(self, key: str, default: Any = _REQUIRED) -> Point:
        value = self.raw(key, default)
        if value is default and default is not _REQUIRED:
            return default
        return check_point(self.file, self.key_path(key), value)

    def points(self, key: str, min_count: int) -> Tuple[Point, ...]:
        value = self.raw(key)
        if not isinstance(value, list) or len(value) < min_count:
            raise self.fail(key, value, f'a list of at least {min_count} [x, y] points [m]')
        return tuple(check_point(self.file, f'{self.key_path(key)}[{i}]', p)
                     for i, p in enumerate(value))

    def rect(self, key: str) -> Rect:
        value = self.raw(key)
        ok = isinstance(value, list) and len(value) == 4 and all(_is_coordinate(v) for v in value)
        if not ok or not (value[0] < value[2] and value[1] < value[3]):
            raise self.fail(key, value, '[x_min, y_min, x_max, y_max] [m] with min < max, '
                            f'each within +-{COORDINATE_LIMIT:g}')
        return (float(value[0]), float(value[1]), float(value[2]), float(value[3]))

    def section(self, key: str, required: bool = False) -> 'KeyReader':
        value = self.raw(key, _REQUIRED if required else {})
        return type(self)(self.file, self.key_path(key), value)   # a subclass reads on

    def items(self, key: str, required: bool = True) -> List['KeyReader']:
        value = self.raw(key, _REQUIRED if required else [])
        if not isinstance(value, list) or (required and not value):
            raise self.fail(key, value, 'a non-empty list of mappings' if required else 'a list')
        return [type(self)(self.file, self.key_path(key) + f'[{i}]', item)
                for i, item in enumerate(value)]

    def done(self) -> None:
        """Raise on the first key that no reader asked for."""
        for key in self.data:
            if key not in self.seen:
                raise self.fail(str(key), self.data[key],
                                'no such key here; known keys: ' + ', '.join(sorted(self.seen)))


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_finite(value: Any) -> bool:
    """Return True for an int or float that is a finite float (an int too large for a float
    is not)."""
    if not _is_number(value):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _is_coordinate(value: Any) -> bool:
    return _is_finite(value) and abs(value) <= COORDINATE_LIMIT


def check_number(reader: KeyReader, key: str, value: Any, low: float, high: float,
                  low_open: bool) -> float:
    bracket = '(' if low_open else '['
    expected = f'a finite number in {bracket}{low:g}, {high:g}]'
    if not _is_finite(value):
        raise reader.fail(key, value, expected)
    if value < low or value > high or (low_open and value == low):
        raise reader.fail(key, value, expected)
    return float(value)


def check_point(file: str, path: str, value: Any) -> Point:
    if (not isinstance(value, list) or len(value) != 2
            or not all(_is_coordinate(v) for v in value)):
        raise CellError(file, path, value, 'a point [x, y] of two finite numbers [m] within '
                        f'+-{COORDINATE_LIMIT:g}')
    return (float(value[0]), float(value[1]))
