"""Fault kinds, their parameters and targets, and validation against a cell (no ROS imports).

A fault is a :class:`FaultSpec` (kind, target, parameters, duration) as a user writes it; once
validated against a cell it becomes an :class:`ActiveFault` (with an id, its target's index and
every parameter filled in) that the stages apply. Every kind is listed in :data:`KINDS` with
the target it acts on and its parameters (name -> :class:`Param`: unit, range, default).
"""

from dataclasses import dataclass, field
import math
from typing import Dict, Optional, Tuple

from conveyor_twin import contract
from conveyor_twin.cell.model import Cell

# what a fault acts on
BARRIER = 'light_barrier'
BELT = 'belt'
ACTUATOR = 'actuator'
PART = 'part'
REGION = 'region'
SOURCE = 'source'
STREAM = 'stream'
COMMAND_TOPIC = 'command_topic'

#: Streams a ``stream_outage`` may silence (:data:`conveyor_twin.contract.OUTAGE_STREAMS`).
OUTAGE_STREAMS = tuple(t.name for t in contract.OUTAGE_STREAMS)
#: Command topics a ``command_drop``/``command_delay`` acts on.
COMMAND_TOPICS = tuple(t.name for t in contract.COMMANDS)


@dataclass(frozen=True)
class Param:
    """One parameter of a fault kind: its unit, admissible closed range and default.

    :param low: smallest admissible value. :param high: largest admissible value.
    :param default: the value when not given; None: required.
    :param open_low: ``low`` itself is not admissible.
    """

    unit: str
    low: float
    high: float
    default: Optional[float] = None
    open_low: bool = False


@dataclass(frozen=True)
class Kind:
    """A fault kind: the target it acts on, its parameters and a one-line meaning."""

    target: str
    params: Dict[str, Param]
    meaning: str


_DELAY = Param('s', 0.0, 60.0, open_low=True)
_PROBABILITY = Param('1', 0.0, 1.0, 1.0, open_low=True)
_REGION = {'x0': Param('m', -1e4, 1e4), 'y0': Param('m', -1e4, 1e4),
           'x1': Param('m', -1e4, 1e4), 'y1': Param('m', -1e4, 1e4)}

#: Every fault kind by name.
KINDS: Dict[str, Kind] = {
    'barrier_stuck_blocked': Kind(BARRIER, {}, 'the barrier reports blocked whatever passes'),
    'barrier_stuck_free': Kind(BARRIER, {}, 'the barrier reports free whatever passes'),
    'barrier_chatter': Kind(BARRIER, {'frequency': Param('Hz', 0.0, 500.0, open_low=True)},
                            'the barrier toggles between blocked and free at `frequency`'),
    'barrier_delay': Kind(BARRIER, {'delay': _DELAY},
                          'the barrier reports its state and edges `delay` late'),
    'barrier_drop_edges': Kind(BARRIER, {'probability': _PROBABILITY},
                               'each edge of the barrier is lost with `probability`'),
    'belt_stall': Kind(BELT, {}, 'the belt motor stalls: speed 0 whatever is commanded'),
    'belt_slip': Kind(BELT, {'factor': Param('1', 0.0, 1.0)},
                      'actual speed = `factor` x the drive speed'),
    'belt_speed_noise': Kind(BELT, {'sigma': Param('m/s', 0.0, 10.0, open_low=True)},
                             'actual speed = drive speed + Gaussian noise of std `sigma`'),
    'belt_ignore_commands': Kind(BELT, {}, 'commands to the belt have no effect'),
    'belt_delay_commands': Kind(BELT, {'delay': _DELAY},
                                'commands to the belt take effect `delay` late'),
    'actuator_stuck': Kind(ACTUATOR, {}, 'the actuator stays where it is'),
    'actuator_slow': Kind(ACTUATOR, {'factor': Param('1', 0.0, 1.0, open_low=True)},
                          'the actuator moves at `factor` x its max speed'),
    'actuator_offset': Kind(ACTUATOR, {'offset': Param('m or rad', -1e3, 1e3)},
                            'the actuator sits `offset` from where it is driven (clipped to '
                            'its range), moving there at its speed'),
    'actuator_ignore_commands': Kind(ACTUATOR, {}, 'commands to the actuator have no effect'),
    'actuator_delay_commands': Kind(ACTUATOR, {'delay': _DELAY},
                                    'commands to the actuator take effect `delay` late'),
    'part_jam': Kind(PART, {'x': Param('m', -1e4, 1e4, math.nan),
                            'y': Param('m', -1e4, 1e4, math.nan)},
                     'a part is stuck at its pose (target: the id of a part in the micro '
                     'scale now, or empty and the part nearest to (`x`, `y`))'),
    'parts_vanish': Kind(REGION, dict(_REGION),
                         'parts whose centre enters the rectangle fall off the line'),
    'source_surge': Kind(SOURCE, {'factor': Param('1', 1.0, 100.0, open_low=True)},
                         'the source delivers `factor` x its rate'),
    'source_wrong_type': Kind(SOURCE, {}, 'the source delivers `part_type` instead of its own'),
    'stream_outage': Kind(STREAM, {}, 'the stream is not published'),
    'command_drop': Kind(COMMAND_TOPIC, {'probability': _PROBABILITY},
                         'each message of the command topic is lost with `probability`'),
    'command_delay': Kind(COMMAND_TOPIC, {'delay': _DELAY},
                          'each message of the command topic takes effect `delay` late'),
}

#: Longest duration of a fault [s] (0: until cleared).
MAX_DURATION = 1e6


class FaultRejected(ValueError):
    """A fault request is invalid; the message names the field, the value and what is allowed."""


@dataclass(frozen=True)
class FaultSpec:
    """A fault as requested.

    :param kind: one of :data:`KINDS`.
    :param target: what it acts on: a light barrier, belt, actuator or source name, a part id,
        a stream or command topic name; empty for ``parts_vanish`` (and ``part_jam`` by place).
    :param params: the kind's parameters by name (SI units, see :data:`KINDS`).
    :param duration: clear it after this long [s]; 0: until cleared.
    :param part_type: the part type ``source_wrong_type`` delivers.
    """

    kind: str
    target: str = ''
    params: Dict[str, float] = field(default_factory=dict)
    duration: float = 0.0
    part_type: str = ''


@dataclass(frozen=True)
class ActiveFault:
    """A validated fault with its id (unique in a run) and resolved target.

    :param index: index of the target in the cell (barrier, belt, actuator, source), the part
        id for ``part_jam`` by id (-1: by place), or -1.
    :param params: every parameter of the kind, defaults filled in.
    :param part_type_index: the part type index for ``source_wrong_type``, else -1.
    """

    id: int
    kind: str
    target: str
    index: int
    params: Tuple[Tuple[str, float], ...]
    duration: float
    part_type: str = ''
    part_type_index: int = -1

    def param(self, name: str) -> float:
        """Return the value of parameter ``name``."""
        return dict(self.params)[name]

    def as_dict(self) -> dict:
        """Return the fault as plain data (for the scale processes and recordings)."""
        return {'id': self.id, 'kind': self.kind, 'target': self.target, 'index': self.index,
                'params': [list(p) for p in self.params], 'duration': self.duration,
                'part_type': self.part_type, 'part_type_index': self.part_type_index}

    @classmethod
    def from_dict(cls, data: dict) -> 'ActiveFault':
        """Rebuild a fault from :meth:`as_dict`."""
        return cls(int(data['id']), data['kind'], data['target'], int(data['index']),
                   tuple((str(k), float(v)) for k, v in data['params']),
                   float(data['duration']), data.get('part_type', ''),
                   int(data.get('part_type_index', -1)))


def validate(cell: Cell, spec: FaultSpec, fault_id: int) -> ActiveFault:
    """Return the fault of ``spec`` on ``cell`` with ``fault_id``.

    :raises FaultRejected: for an unknown kind or target, a missing, unknown, non-finite or
        out-of-range parameter, or an invalid duration; the message names which.
    """
    kind = KINDS.get(spec.kind)
    if kind is None:
        raise FaultRejected(f'kind {spec.kind!r} is unknown (known: {", ".join(KINDS)})')
    where = f'fault {spec.kind!r}'
    if not isinstance(spec.duration, (int, float)) or not math.isfinite(spec.duration) \
            or not 0.0 <= spec.duration <= MAX_DURATION:
        raise FaultRejected(f'{where}: duration {spec.duration!r} s is outside '
                            f'[0, {MAX_DURATION:g}] s (0: until cleared)')
    params = _params(where, kind, spec.params)
    index, part_type_index = _target(cell, where, kind, spec, params)
    return ActiveFault(fault_id, spec.kind, spec.target, index, tuple(sorted(params.items())),
                       float(spec.duration), spec.part_type, part_type_index)


def _params(where: str, kind: Kind, given: Dict[str, float]) -> Dict[str, float]:
    unknown = sorted(set(given) - set(kind.params))
    if unknown:
        allowed = ', '.join(kind.params) or 'none'
        raise FaultRejected(f'{where}: parameter {unknown[0]!r} is unknown (allowed: {allowed})')
    out = {}
    for name, p in kind.params.items():
        value = given.get(name, p.default)
        if value is None:
            raise FaultRejected(f'{where}: parameter {name!r} [{p.unit}] is required')
        try:
            value = float(value)
        except (TypeError, ValueError):
            raise FaultRejected(f'{where}: parameter {name!r} is {value!r}, not a number') \
                from None
        if name in given and not math.isfinite(value):
            raise FaultRejected(f'{where}: parameter {name!r} is {value!r}, not finite')
        if math.isfinite(value) and not (p.low < value if p.open_low else p.low <= value) \
                or math.isfinite(value) and value > p.high:
            low = '(' if p.open_low else '['
            unit = '' if p.unit == '1' else f' {p.unit}'
            raise FaultRejected(f'{where}: parameter {name!r} = {value!r}{unit} is outside '
                                f'{low}{p.low:g}, {p.high:g}]{unit}')
        out[name] = value
    return out


def no_such_part(part_id: int) -> FaultRejected:
    """The rejection of a ``part_jam`` on a part id the micro scale does not hold now."""
    return FaultRejected(f"fault 'part_jam': target {str(part_id)!r}: no such part exists now "
                         '(no part of that id is in the micro scale: never placed, left '
                         'through a sink, fell off, or handed over to the macro scale)')


def _named(where: str, what: str, target: str, names) -> int:
    names = list(names)
    if target not in names:
        raise FaultRejected(f'{where}: {what} {target!r} is unknown (known: '
                            f'{", ".join(names) or "none"})')
    return names.index(target)


def _target(cell: Cell, where: str, kind: Kind, spec: FaultSpec,
            params: Dict[str, float]) -> Tuple[int, int]:
    """Return (target index, part type index) of a fault, or raise FaultRejected."""
    target = spec.target
    if spec.part_type and spec.kind != 'source_wrong_type':
        raise FaultRejected(f'{where}: part_type is only for source_wrong_type')
    if kind.target == BARRIER:
        return _named(where, 'light barrier', target, (b.name for b in cell.light_barriers)), -1
    if kind.target == BELT:
        return _named(where, 'belt', target, (b.name for b in cell.belts)), -1
    if kind.target == ACTUATOR:
        index = _named(where, 'actuator', target, (a.name for a in cell.actuators))
        if spec.kind == 'actuator_offset':
            low, high = cell.actuators[index].position_range
            if abs(params['offset']) > high - low:
                raise FaultRejected(f'{where}: offset {params["offset"]!r} is larger than the '
                                    f'stroke of {target!r} ({high - low:g})')
        return index, -1
    if kind.target == SOURCE:
        index = _named(where, 'source', target, (s.name for s in cell.sources))
        if spec.kind != 'source_wrong_type':
            return index, -1
        names = [p.name for p in cell.part_types]
        if spec.part_type not in names:
            raise FaultRejected(f'{where}: part_type {spec.part_type!r} is unknown (known: '
                                f'{", ".join(names)})')
        return index, names.index(spec.part_type)
    if kind.target == STREAM:
        return _named(where, 'stream', target, OUTAGE_STREAMS), -1
    if kind.target == COMMAND_TOPIC:
        return _named(where, 'command topic', target, COMMAND_TOPICS), -1
    if kind.target == REGION:
        if target:
            raise FaultRejected(f'{where}: target must be empty (the region is x0, y0, x1, y1)')
        if not (params['x0'] < params['x1'] and params['y0'] < params['y1']):
            raise FaultRejected(f'{where}: region x0 {params["x0"]:g} .. x1 {params["x1"]:g}, '
                                f'y0 {params["y0"]:g} .. y1 {params["y1"]:g} is empty')
        return -1, -1
    # part_jam: a part id, or empty and a place
    if target:
        if not target.isdigit() or int(target) < 1:
            raise FaultRejected(f'{where}: target {target!r} is not a part id (an integer >= 1'
                                '; or empty with x and y)')
        return int(target), -1
    if not (math.isfinite(params['x']) and math.isfinite(params['y'])):
        raise FaultRejected(f'{where}: give a part id as target, or x and y of a place')
    return -1, -1
