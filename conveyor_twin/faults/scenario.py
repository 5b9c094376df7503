"""Scenario files: faults scheduled by step or time, or triggered by what happens in the cell.

A scenario is YAML (``safe_load``), validated against the cell before the twin starts, with
errors that name the file, the key path, the value and what is allowed::

    name: stuck exit barrier        # optional
    faults:
      - kind: barrier_stuck_blocked
        target: lb_exit
        at: {time: 2.0}               # or {step: N}, {after_edges: {barrier: B, count: N}},
                                      #    {zone_parts_above: {zone: Z, count: K}}
        duration: 1.5                 # optional [s]; 0 or absent: until cleared
        params: {}                    # the kind's parameters (docs/faults.md)
        part_type: ''                 # source_wrong_type only

``step``/``time`` faults take effect at that step (time rounded to the nearest step, at least
step 1). A trigger is checked after every step and its fault takes effect at the next one:
``after_edges`` once the barrier has reported ``count`` edges since the start,
``zone_parts_above`` once more than ``count`` parts are in the zone (bodies with their centre
in it plus the macro density's parts). Every entry fires once per run (again after a reset).
Split over processes, the scale nodes measure the edge counts and zone parts after every step
and send them with their step replies (only for a scenario with such triggers), so the
triggers fire at the same step as composed.
"""

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any, Callable, List, Optional, Tuple

import numpy as np
import yaml

from conveyor_twin.cell.errors import CellError
from conveyor_twin.cell.model import Cell
from conveyor_twin.faults.book import FaultBook
from conveyor_twin.faults.model import FaultRejected, FaultSpec, KINDS, validate

TRIGGERS = ('step', 'time', 'after_edges', 'zone_parts_above')


class ScenarioError(CellError):
    """A scenario file is invalid; the message names file, key path, value and expectation."""


@dataclass(frozen=True)
class ScenarioEntry:
    """One fault of a scenario and when it starts.

    :param trigger: ``step`` (``step`` set), ``after_edges`` (``index``: barrier, ``count``) or
        ``zone_parts_above`` (``index``: zone, ``count``); ``time`` is turned into ``step``.
    """

    spec: FaultSpec
    trigger: str
    step: int = 0
    index: int = -1
    count: int = 0
    text: str = ''

    @property
    def conditional(self) -> bool:
        """True for a trigger checked after every step."""
        return self.trigger != 'step'


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: its name, entries, file and YAML text (recorded with a run)."""

    name: str
    entries: Tuple[ScenarioEntry, ...]
    source_file: str
    text: str

    @property
    def conditional(self) -> bool:
        """True if an entry is triggered by the cell's state."""
        return any(e.conditional for e in self.entries)


def load_scenario(path: str, cell: Cell) -> Scenario:
    """Read and validate a scenario file against ``cell``.

    :raises ScenarioError: if it cannot be read or is invalid.
    """
    try:
        text = Path(path).read_text('utf-8')
    except (OSError, ValueError) as exc:
        raise ScenarioError(str(path), '<file>', str(exc), 'a readable UTF-8 YAML file') \
            from None
    return scenario_from_text(text, cell, str(path))


def scenario_from_text(text: str, cell: Cell, source_file: str = '<memory>') -> Scenario:
    """Validate the YAML ``text`` of a scenario against ``cell``.

    :raises ScenarioError: if it is not YAML or not a valid scenario.
    """
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f'line {mark.line + 1}, column {mark.column + 1}' if mark else '<document>'
        raise ScenarioError(source_file, where, str(getattr(exc, 'problem', exc)),
                            'valid YAML') from None
    err = _Errors(source_file)
    if not isinstance(data, dict):
        raise err('<document>', data, 'a mapping with `faults` (and an optional `name`)')
    unknown = sorted(set(data) - {'name', 'faults'})
    if unknown:
        raise err(unknown[0], data[unknown[0]], 'only the keys name and faults')
    faults = data.get('faults')
    if not isinstance(faults, list) or not faults:
        raise err('faults', faults, 'a non-empty list of faults')
    entries = tuple(_entry(err, f'faults[{i}]', item, cell) for i, item in enumerate(faults))
    return Scenario(str(data.get('name', '') or Path(source_file).stem), entries, source_file,
                    text)


class _Errors:
    def __init__(self, source_file: str) -> None:
        self.source_file = source_file

    def __call__(self, key: str, value: Any, expected: str) -> ScenarioError:
        return ScenarioError(self.source_file, key, value, expected)


def _number(err: _Errors, key: str, value: Any, low: float, integer: bool = False) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) \
        and math.isfinite(value) and value >= low and (not integer or float(value).is_integer())
    if not ok:
        what = 'an integer' if integer else 'a finite number'
        raise err(key, value, f'{what} >= {low:g}')
    return value


def _entry(err: _Errors, key: str, item: Any, cell: Cell) -> ScenarioEntry:
    if not isinstance(item, dict):
        raise err(key, item, 'a mapping with kind, target, at, and optionally duration, '
                  'params, part_type')
    unknown = sorted(set(item) - {'kind', 'target', 'at', 'duration', 'params', 'part_type'})
    if unknown:
        raise err(f'{key}.{unknown[0]}', item[unknown[0]],
                  'one of kind, target, at, duration, params, part_type')
    kind = item.get('kind')
    if kind not in KINDS:
        raise err(f'{key}.kind', kind, f'one of {", ".join(KINDS)}')
    params = item.get('params', {}) or {}
    if not isinstance(params, dict):
        raise err(f'{key}.params', params, 'a mapping of parameter names to numbers')
    for name, value in params.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise err(f'{key}.params.{name}', value, 'a number')
    target = item.get('target', '')
    target = str(target) if isinstance(target, int) and not isinstance(target, bool) else target
    if not isinstance(target, str):
        raise err(f'{key}.target', target, 'a name (string), or a part id')
    duration = _number(err, f'{key}.duration', item.get('duration', 0.0), 0.0)
    spec = FaultSpec(kind, target, {str(k): float(v) for k, v in params.items()},
                     float(duration), str(item.get('part_type', '') or ''))
    try:
        validate(cell, spec, 0)
    except FaultRejected as exc:
        raise err(key, item, f'a valid fault ({exc})') from None
    at = item.get('at')
    if not isinstance(at, dict) or len(at) != 1 or next(iter(at)) not in TRIGGERS:
        raise err(f'{key}.at', at, 'one of {step: N}, {time: T}, {after_edges: {barrier: B, '
                  'count: N}}, {zone_parts_above: {zone: Z, count: K}}')
    trigger, value = next(iter(at.items()))
    where = f'{key}.at.{trigger}'
    text = f'{trigger} {value}'
    if trigger == 'step':
        return ScenarioEntry(spec, 'step', step=int(_number(err, where, value, 1, True)),
                             text=text)
    if trigger == 'time':
        seconds = _number(err, where, value, 0.0)
        return ScenarioEntry(spec, 'step', step=max(1, int(round(seconds / cell.settings.step))),
                             text=text)
    # a trigger on the cell's state: (key of the element, what it is, its names, least count)
    key, what, names, least = (
        ('barrier', 'a light barrier', [b.name for b in cell.light_barriers], 1)
        if trigger == 'after_edges' else ('zone', 'a zone', [z.name for z in cell.zones], 0))
    if not isinstance(value, dict) or set(value) != {key, 'count'}:
        raise err(where, value, f'a mapping with exactly {key} and count')
    if value[key] not in names:
        raise err(f'{where}.{key}', value[key],
                  f'{what} of the cell ({", ".join(names) or "none"})')
    count = int(_number(err, f'{where}.count', value['count'], least, True))
    text = (f'after {count} edges of {value[key]}' if trigger == 'after_edges'
            else f'more than {count} parts in zone {value[key]}')
    return ScenarioEntry(spec, trigger, index=names.index(value[key]), count=count, text=text)


class ScenarioRunner:
    """Arms a scenario on a twin: schedules its timed faults and checks its triggers.

    :param scenario: the validated scenario.
    :param faults: the twin's fault book.
    :param edge_count: returns the reported edge count of every light barrier (conditional
        triggers), or None.
    :param zone_parts: returns the parts in zone ``index`` (bodies and density), or None.
    """

    def __init__(self, scenario: Scenario, faults: FaultBook, *,
                 edge_count: Optional[Callable[[], np.ndarray]] = None,
                 zone_parts: Optional[Callable[[int], float]] = None) -> None:
        if scenario.conditional and (edge_count is None or zone_parts is None):
            raise ValueError('this scenario has triggers on the cell\'s state: give edge_count '
                             'and zone_parts')
        self.scenario = scenario
        self.faults = faults
        self.edge_count = edge_count
        self.zone_parts = zone_parts
        self.fired = 0
        self.arm()

    def arm(self) -> None:
        """Schedule the timed faults and await the triggers (at the start and after a reset)."""
        self._waiting: List[ScenarioEntry] = []
        for entry in self.scenario.entries:
            if entry.conditional:
                self._waiting.append(entry)
            else:
                try:
                    self.faults.inject(entry.spec, step=entry.step, reason='scenario')
                except FaultRejected:  # another cell after a reset: counted by the book
                    pass

    def watch(self, inp: Any) -> None:
        """Check the triggers after a step; a fired one takes effect at the next step."""
        if not self._waiting:
            return
        fired = []
        counts = None
        for entry in self._waiting:
            if entry.trigger == 'after_edges':
                if counts is None:
                    counts = self.edge_count()
                hit = int(counts[entry.index]) >= entry.count
            else:
                hit = self.zone_parts(entry.index) > entry.count
            if hit:
                fired.append(entry)
        for entry in fired:
            self._waiting.remove(entry)
            try:
                self.faults.inject(entry.spec, step=inp.step + 1,
                                   reason=f'scenario: {entry.text}')
            except FaultRejected:
                continue
            self.fired += 1
