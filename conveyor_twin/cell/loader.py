"""Read a cell YAML file into validated :class:`~conveyor_twin.cell.model.Cell` dataclasses.

YAML is parsed only with ``yaml.safe_load`` (the pure-Python parser: libyaml's recurses on the
C stack and crashes the process on deeply nested text, where this one raises RecursionError,
reported as a CellError). Unknown keys, wrong types, out-of-range values,
missing required keys, duplicate names and dangling references are :class:`CellError` naming
the file, the key path, the value and what was expected.
"""

from importlib import resources
import math
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, TypeVar, Union

import yaml

from conveyor_twin.cell.errors import CellError
from conveyor_twin.cell.model import (
    ACTUATOR_KINDS, Actuator, AutoSwitch, Belt, Cell, CONTACT_MODELS, ContactModel, LightBarrier,
    MACRO_SCHEMES, MACRO_VARIANTS, MacroModel, MacroScheme, MacroVariant, MicroModel, Obstacle,
    OBSTACLE_KINDS, ObstacleKind, PART_SHAPES, PartType, Point, Rect, Settings, Sink, Source,
    SOURCE_PATTERNS, Zone, ZONE_POLICIES, ZonePolicy,
)

DEFAULT_CELL_NAME = 'default_cell.yaml'
#: Largest coordinate of a point or rectangle [m]: a cell spans at most 2 km in x and in y.
COORDINATE_LIMIT = 1000.0
_REQUIRED = object()
_INF = math.inf
T = TypeVar('T')


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
        return _check_number(self, key, value, low, high, low_open)

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

    def point(self, key: str, default: Any = _REQUIRED) -> Point:
        value = self.raw(key, default)
        if value is default and default is not _REQUIRED:
            return default
        return _check_point(self.file, self.key_path(key), value)

    def points(self, key: str, min_count: int) -> Tuple[Point, ...]:
        value = self.raw(key)
        if not isinstance(value, list) or len(value) < min_count:
            raise self.fail(key, value, f'a list of at least {min_count} [x, y] points [m]')
        return tuple(_check_point(self.file, f'{self.key_path(key)}[{i}]', p)
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


def _check_number(reader: KeyReader, key: str, value: Any, low: float, high: float,
                  low_open: bool) -> float:
    bracket = '(' if low_open else '['
    expected = f'a finite number in {bracket}{low:g}, {high:g}]'
    if not _is_finite(value):
        raise reader.fail(key, value, expected)
    if value < low or value > high or (low_open and value == low):
        raise reader.fail(key, value, expected)
    return float(value)


def _check_point(file: str, path: str, value: Any) -> Point:
    if (not isinstance(value, list) or len(value) != 2
            or not all(_is_coordinate(v) for v in value)):
        raise CellError(file, path, value, 'a point [x, y] of two finite numbers [m] within '
                        f'+-{COORDINATE_LIMIT:g}')
    return (float(value[0]), float(value[1]))


def _unique(readers: List[KeyReader], items: Sequence[T], what: str) -> None:
    names: Dict[str, int] = {}
    for reader, item in zip(readers, items):
        name = getattr(item, 'name')
        if name in names:
            raise reader.fail('name', name, f'a {what} name not used before')
        names[name] = 1


def _settings(r: KeyReader) -> Settings:
    settings = Settings(
        name=r.string('name'),
        frame_id=r.string('frame_id', 'cell'),
        step=r.number('step', 1e-3, low=1e-6, high=0.1),
        gravity=r.number('gravity', 9.81, low=0.0, high=100.0),
        seed=r.integer('seed', 0),
    )
    r.done()
    return settings


def _belt(r: KeyReader) -> Belt:
    start, end = r.point('start'), r.point('end')
    if math.hypot(end[0] - start[0], end[1] - start[1]) <= 0.0:
        raise r.fail('end', list(end), 'a point different from start (a belt of positive length)')
    max_speed = r.number('max_speed', 2.0, low=0.0, high=20.0, low_open=True)
    belt = Belt(
        name=r.string('name'), start=start, end=end,
        width=r.number('width', low=0.0, high=10.0, low_open=True),
        speed=r.number('speed', 0.0, low=-max_speed, high=max_speed),
        max_speed=max_speed,
        acceleration=r.number('acceleration', 1.0, low=0.0, high=1000.0, low_open=True),
        friction=r.number('friction', 0.3, low=0.0, high=5.0, low_open=True),
    )
    r.done()
    return belt


def _is_convex_ccw(points: Tuple[Point, ...]) -> bool:
    n = len(points)
    for i in range(n):
        (x0, y0), (x1, y1), (x2, y2) = points[i], points[(i + 1) % n], points[(i + 2) % n]
        if (x1 - x0) * (y2 - y1) - (y1 - y0) * (x2 - x1) <= 0.0:
            return False
    return True


def _obstacle(r: KeyReader) -> Obstacle:
    name = r.string('name')
    kind = ObstacleKind(r.string('kind', choices=OBSTACLE_KINDS))
    thickness, radius = 0.0, 0.0
    if kind == ObstacleKind.PEG:
        points = (r.point('center'),)
        radius = r.number('radius', low=0.0, high=10.0, low_open=True)
    elif kind == ObstacleKind.POLYGON:
        points = r.points('points', 3)
        if not _is_convex_ccw(points):
            if _is_convex_ccw(tuple(reversed(points))):
                points = tuple(reversed(points))
            else:
                raise r.fail('points', [list(p) for p in points],
                             'the corners of a convex polygon with no repeated corner')
    else:
        points = r.points('points', 2)
        for i in range(1, len(points)):
            if points[i] == points[i - 1]:
                raise r.fail('points', [list(p) for p in points],
                             'a polyline with no zero-length segment')
        thickness = r.number('thickness', 0.01 if kind == ObstacleKind.DEFLECTOR else 0.005,
                             low=0.0, high=1.0, low_open=True)
    obstacle = Obstacle(
        name=name, kind=kind, points=points, thickness=thickness, radius=radius,
        restitution=r.number('restitution', 0.3, low=0.0, high=1.0),
        friction=r.number('friction', 0.2, low=0.0, high=5.0),
    )
    r.done()
    return obstacle


def _part_type(r: KeyReader) -> PartType:
    name = r.string('name')
    shape = r.string('shape', choices=PART_SHAPES)
    mass = r.number('mass', low=0.0, high=1e3, low_open=True)
    radius = length = width = 0.0
    if shape == 'disc':
        radius = r.number('radius', low=0.0, high=1.0, low_open=True)
        default_inertia = 0.5 * mass * radius ** 2
    else:
        length = r.number('length', low=0.0, high=2.0, low_open=True)
        width = r.number('width', low=0.0, high=2.0, low_open=True)
        default_inertia = mass * (length ** 2 + width ** 2) / 12.0
    static = r.number('friction_static', 0.3, low=0.0, high=5.0)
    part_type = PartType(
        name=name, shape=shape, radius=radius, length=length, width=width,
        height=r.number('height', low=0.0, high=2.0, low_open=True),
        mass=mass,
        inertia=r.number('inertia', default_inertia, low=0.0, high=1e3, low_open=True),
        restitution=r.number('restitution', 0.3, low=0.0, high=1.0),
        friction_static=static,
        friction_sliding=r.number('friction_sliding', static, low=0.0, high=static),
        friction_transition_speed=r.number('friction_transition_speed', 0.01, low=0.0,
                                           high=10.0, low_open=True),
    )
    r.done()
    return part_type


def _source(r: KeyReader, part_names: Sequence[str]) -> Source:
    name = r.string('name')
    part_type = r.string('part_type')
    if part_type not in part_names:
        raise r.fail('part_type', part_type,
                     'the name of a part type in part_types: ' + ', '.join(part_names))
    velocity = r.raw('velocity', 'belt')
    if velocity != 'belt':
        velocity = _check_point(r.file, r.key_path('velocity'), velocity)
    else:
        velocity = None
    yaw = r.raw('yaw', 'random')
    if yaw != 'random':
        yaw = _check_number(r, 'yaw', yaw, -math.pi, math.pi, False)
    else:
        yaw = None
    source = Source(
        name=name, part_type=part_type, region=r.rect('region'),
        rate=r.number('rate', low=0.0, high=1e5, low_open=True),
        pattern=r.string('pattern', 'uniform', choices=SOURCE_PATTERNS),
        burst_size=r.integer('burst_size', 1, low=1, high=100000),
        velocity=velocity, yaw=yaw,
        start_time=r.number('start_time', 0.0, low=0.0, high=1e7),
        max_parts=r.integer('max_parts', 0),
        seed=r.integer('seed', 0),
    )
    r.done()
    return source


def _sink(r: KeyReader) -> Sink:
    sink = Sink(name=r.string('name'), region=r.rect('region'))
    r.done()
    return sink


def _light_barrier(r: KeyReader) -> LightBarrier:
    start, end = r.point('start'), r.point('end')
    if start == end:
        raise r.fail('end', list(end), 'a point different from start (a beam of positive length)')
    barrier = LightBarrier(name=r.string('name'), start=start, end=end,
                           height=r.number('height', low=0.0, high=2.0))
    r.done()
    return barrier


def _actuator(r: KeyReader) -> Actuator:
    name = r.string('name')
    kind = r.string('kind', choices=ACTUATOR_KINDS)
    axis = r.point('axis')
    norm = math.hypot(*axis)
    if norm == 0.0:
        raise r.fail('axis', list(axis), 'a non-zero direction [x, y]')
    axis = (axis[0] / norm, axis[1] / norm)
    unit = 'rad' if kind == 'diverter' else 'm'
    if kind == 'diverter':
        low = r.number('min_position', 0.0, low=-math.pi, high=math.pi)
        high = r.number('max_position', low=-math.pi, high=math.pi)
    else:
        low = 0.0
        high = r.number('stroke', low=0.0, high=10.0, low_open=True)
    if high <= low:
        raise r.fail('max_position', high, f'a value above min_position {low:g} [{unit}]')
    initial = r.number('initial_position', low, low=low, high=high)
    engage = 0.0
    if kind == 'stopper':
        engage = r.number('engage_height', 0.5 * high, low=0.0, high=high, low_open=True)
    actuator = Actuator(
        name=name, kind=kind, base=r.point('base'), axis=axis,
        length=r.number('length', low=0.0, high=10.0, low_open=True),
        width=r.number('width', low=0.0, high=10.0, low_open=True),
        position_range=(low, high),
        max_speed=r.number('max_speed', low=0.0, high=100.0, low_open=True),
        initial_position=initial, engage_height=engage,
        restitution=r.number('restitution', 0.2, low=0.0, high=1.0),
        friction=r.number('friction', 0.2, low=0.0, high=5.0),
    )
    r.done()
    return actuator


def _zone(r: KeyReader) -> Zone:
    name = r.string('name')
    policy = ZonePolicy(r.string('policy', 'micro', choices=ZONE_POLICIES))
    region = r.rect('region')
    resolution = r.number('resolution', 0.01, low=0.0, high=1.0, low_open=True)
    a = r.section('auto')
    to_micro = a.number('to_micro_density', 1500.0, low=0.0, high=1e12)
    auto = AutoSwitch(
        tile=a.number('tile', 0.25, low=resolution, high=100.0),
        to_macro_density=a.number('to_macro_density', 4000.0, low=to_micro, high=1e12,
                                  low_open=True),
        to_micro_density=to_micro,
        min_dwell=a.number('min_dwell', 0.5, low=0.0, high=1e6),
        sensor_margin=a.number('sensor_margin', 0.1, low=0.0, high=100.0),
        free_flow_slip=a.number('free_flow_slip', 0.0, low=0.0, high=1.0),
    )
    a.done()
    r.done()
    return Zone(name=name, policy=policy, region=region, resolution=resolution, auto=auto)


def _micro(r: KeyReader) -> MicroModel:
    model = MicroModel(
        contact=ContactModel(r.string('contact', 'impulse', choices=CONTACT_MODELS)),
        capacity=r.integer('capacity', 20000, low=1, high=10_000_000),
        penetration_slop=r.number('penetration_slop', 1e-4, low=0.0, high=0.01),
        penetration_correction=r.number('penetration_correction', 0.8, low=0.0, high=1.0),
        penalty_stiffness=r.number('penalty_stiffness', 1e5, low=0.0, high=1e9,
                                   low_open=True),
        penalty_damping=r.number('penalty_damping', 5.0, low=0.0, high=1e6),
        max_travel_fraction=r.number('max_travel_fraction', 0.5, low=0.0, high=1.0,
                                     low_open=True),
    )
    r.done()
    return model


def _macro(r: KeyReader) -> MacroModel:
    model = MacroModel(
        variant=MacroVariant(r.string('variant', 'goettlich', choices=MACRO_VARIANTS)),
        scheme=MacroScheme(r.string('scheme', 'upwind', choices=MACRO_SCHEMES)),
        rho_max=r.number('rho_max', 0.0, low=0.0, high=1e7),
        epsilon=r.number('epsilon', 0.5, low=0.0, high=1e3),
        mollifier_width=r.number('mollifier_width', 0.0, low=0.0, high=10.0),
        cfl=r.number('cfl', 0.9, low=0.0, high=1.0, low_open=True),
    )
    r.done()
    return model


def _list(top: KeyReader, key: str, build: Callable[[KeyReader], T], what: str,
          required: bool = False) -> Tuple[T, ...]:
    readers = top.items(key, required=required)
    items = [build(reader) for reader in readers]
    _unique(readers, items, what)
    return tuple(items)


def cell_from_mapping(data: Any, source_file: str = '<memory>') -> Cell:
    """Validate a parsed YAML document and build the :class:`Cell`.

    :param data: the document as ``yaml.safe_load`` returns it.
    :param source_file: name used in error messages.
    :raises CellError: on the first problem found.
    """
    top = KeyReader(source_file, '', data)
    settings = _settings(top.section('cell', required=True))
    belts = _list(top, 'belts', _belt, 'belt', required=True)
    obstacles = _list(top, 'obstacles', _obstacle, 'obstacle')
    part_types = _list(top, 'part_types', _part_type, 'part type', required=True)
    if len(part_types) > 65535:
        raise top.fail('part_types', len(part_types), 'at most 65535 part types (uint16)')
    names = [p.name for p in part_types]
    sources = _list(top, 'sources', lambda r: _source(r, names), 'source')
    sinks = _list(top, 'sinks', _sink, 'sink')
    barriers = _list(top, 'light_barriers', _light_barrier, 'light barrier')
    actuators = _list(top, 'actuators', _actuator, 'actuator')
    zones = _list(top, 'zones', _zone, 'zone')
    micro = _micro(top.section('micro'))
    macro = _macro(top.section('macro'))
    top.done()
    _check_macro_barriers(source_file, barriers, zones)
    if not zones:
        x0, y0, x1, y1 = _belts_bounds(belts)
        zones = (Zone(name='all', policy=ZonePolicy.MICRO, region=(x0, y0, x1, y1),
                      resolution=0.01),)
    return Cell(source_file=source_file, settings=settings, belts=belts, obstacles=obstacles,
                part_types=part_types, sources=sources, sinks=sinks, light_barriers=barriers,
                actuators=actuators, zones=zones, micro=micro, macro=macro)


def _check_macro_barriers(file: str, barriers: Sequence[LightBarrier],
                          zones: Sequence[Zone]) -> None:
    """Barriers inside a ``macro`` zone are modelled on its grid: they must run along x or y."""
    for k, b in enumerate(barriers):
        mx, my = 0.5 * (b.start[0] + b.end[0]), 0.5 * (b.start[1] + b.end[1])
        for z in zones:
            x0, y0, x1, y1 = z.region
            if z.policy != ZonePolicy.MACRO or not (x0 <= mx <= x1 and y0 <= my <= y1):
                continue
            if abs(b.start[0] - b.end[0]) > 1e-9 and abs(b.start[1] - b.end[1]) > 1e-9:
                raise CellError(file, f'light_barriers[{k}].end', list(b.end),
                                f'a beam along x or y (start {list(b.start)}): it lies in '
                                f'macro zone {z.name!r}, where only such beams are modelled')


def _belts_bounds(belts: Sequence[Belt]) -> Rect:
    xs = [c[0] for belt in belts for c in belt.corners()]
    ys = [c[1] for belt in belts for c in belt.corners()]
    return (min(xs), min(ys), max(xs), max(ys))


def load_cell_text(text: str, source_file: str = '<memory>') -> Cell:
    """Parse YAML ``text`` (``safe_load`` only) and validate it into a :class:`Cell`.

    :raises CellError: if the text is not YAML or not a valid cell.
    """
    try:
        data = yaml.safe_load(text)
    except RecursionError:
        raise CellError(source_file, '<document>', text[:40] + '...',
                        'YAML nested less deeply (the parser ran out of stack)') from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f'line {mark.line + 1}, column {mark.column + 1}' if mark else '<document>'
        raise CellError(source_file, where, str(getattr(exc, 'problem', exc)),
                        'valid YAML') from None
    return cell_from_mapping(data, source_file)


def default_cell_text() -> str:
    """Return the YAML text of the embedded default cell (Hoher et al.'s test rig)."""
    return resources.files('conveyor_twin.cell').joinpath(DEFAULT_CELL_NAME).read_text('utf-8')


def load_cell(path: Optional[Union[str, Path]] = None) -> Cell:
    """Load a cell file, or the embedded default cell when ``path`` is None or empty.

    :raises CellError: if the file cannot be read or is not a valid cell.
    """
    if not path:
        return load_cell_text(default_cell_text(), f'<embedded {DEFAULT_CELL_NAME}>')
    path = Path(path)
    try:
        text = path.read_text('utf-8')
    except (OSError, ValueError) as exc:  # ValueError: undecodable bytes, a NUL in the path
        raise CellError(str(path), '<file>', str(exc), 'a readable UTF-8 YAML file') from None
    return load_cell_text(text, str(path))
