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
from conveyor_twin.cell.loader_curves import check_rail_names, guide_rails, read_curve
from conveyor_twin.cell.reader import check_number, check_point, COORDINATE_LIMIT, KeyReader
from conveyor_twin.cell.model import (
    ACTUATOR_KINDS, Actuator, AutoSwitch, Belt, Cell, CONTACT_MODELS, CONTACT_SWEEP_BUDGET,
    CONTACT_SWEEPS, CONTACT_SWEEPS_MAX, CONTACT_TOLERANCE, CONTACT_TOLERANCE_MAX, ContactModel,
    LightBarrier, MACRO_SCHEMES, MACRO_VARIANTS, MacroModel, MacroScheme, MacroVariant, MicroModel,
    Obstacle, OBSTACLE_KINDS, ObstacleKind, PART_SHAPES, PartType, Point, Rect, Settings, Sink,
    Source, SOURCE_PATTERNS, Zone, ZONE_POLICIES, ZonePolicy,
)

__all__ = ['cell_from_mapping', 'COORDINATE_LIMIT', 'default_cell_text', 'KeyReader',
           'load_cell', 'load_cell_text']

DEFAULT_CELL_NAME = 'default_cell.yaml'
T = TypeVar('T')


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
    curve = None
    if 'curve' in r.data:
        curve, start, end, width = read_curve(r)
    else:
        start, end = r.point('start'), r.point('end')
        if math.hypot(end[0] - start[0], end[1] - start[1]) <= 0.0:
            raise r.fail('end', list(end),
                         'a point different from start (a belt of positive length)')
        width = r.number('width', low=0.0, high=10.0, low_open=True)
    max_speed = r.number('max_speed', 2.0, low=0.0, high=20.0, low_open=True)
    belt = Belt(
        name=r.string('name'), start=start, end=end, width=width,
        speed=r.number('speed', 0.0, low=-max_speed, high=max_speed),
        max_speed=max_speed,
        acceleration=r.number('acceleration', 1.0, low=0.0, high=1000.0, low_open=True),
        friction=r.number('friction', 0.3, low=0.0, high=5.0, low_open=True),
        curve=curve,
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
        velocity = check_point(r.file, r.key_path('velocity'), velocity)
    else:
        velocity = None
    yaw = r.raw('yaw', 'random')
    if yaw != 'random':
        yaw = check_number(r, 'yaw', yaw, -math.pi, math.pi, False)
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
    engage, surface_speed = 0.0, 0.0
    if kind in ('stopper', 'transfer'):
        engage = r.number('engage_height', 0.5 * high, low=0.0, high=high, low_open=True)
    if kind == 'transfer':
        surface_speed = r.number('surface_speed', low=0.0, high=20.0, low_open=True)
    actuator = Actuator(
        name=name, kind=kind, base=r.point('base'), axis=axis,
        length=r.number('length', low=0.0, high=10.0, low_open=True),
        width=r.number('width', low=0.0, high=10.0, low_open=True),
        position_range=(low, high),
        max_speed=_max_speed(r, kind, high),
        initial_position=initial, engage_height=engage,
        restitution=r.number('restitution', 0.2, low=0.0, high=1.0),
        friction=r.number('friction', 0.5 if kind == 'transfer' else 0.2, low=0.0, high=5.0),
        surface_speed=surface_speed,
        force_limit=_force_limit(r),
    )
    r.done()
    return actuator


def _max_speed(r: KeyReader, kind: str, stroke: float) -> float:
    """Read ``max_speed``, or for a transfer ``travel_time`` [s] instead (stroke / time)."""
    if kind != 'transfer' or 'travel_time' not in r.data:
        return r.number('max_speed', low=0.0, high=100.0, low_open=True)
    if 'max_speed' in r.data:
        r.seen.add('max_speed')
        raise r.fail('max_speed', r.data['max_speed'],
                     'either max_speed or travel_time, not both')
    travel_time = r.number('travel_time', low=0.0, high=1e3, low_open=True)
    if stroke / travel_time > 100.0:
        raise r.fail('travel_time', travel_time, f'at least {stroke / 100.0:g} s (a lift speed '
                     f'stroke / travel_time of at most 100 m/s)')
    return stroke / travel_time


def _force_limit(r: KeyReader) -> float:
    """Read ``force_limit`` [N]: (0, 1e7], or ``.inf`` (the default) for unlimited."""
    value = r.raw('force_limit', math.inf)
    if isinstance(value, float) and value == math.inf:
        return math.inf
    if not isinstance(value, (int, float)) or isinstance(value, bool) or not 0.0 < value <= 1e7:
        raise r.fail('force_limit', value, 'a force in (0, 1e+07] [N], or .inf (unlimited)')
    return float(value)


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
        contact_sweeps=r.integer('contact_sweeps', CONTACT_SWEEPS, low=1, high=10_000),
        contact_sweeps_max=r.integer('contact_sweeps_max', CONTACT_SWEEPS_MAX, low=1,
                                     high=10_000),
        contact_sweep_budget=r.integer('contact_sweep_budget', CONTACT_SWEEP_BUDGET, low=0,
                                       high=1_000_000_000),
        contact_tolerance=r.number('contact_tolerance', CONTACT_TOLERANCE, low=0.0,
                                    high=CONTACT_TOLERANCE_MAX),
    )
    r.done()
    if model.contact_sweeps_max < model.contact_sweeps:
        raise r.fail('contact_sweeps_max', model.contact_sweeps_max,
                     f'an integer at least contact_sweeps ({model.contact_sweeps})')
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
    rails = guide_rails(belts)
    check_rail_names(source_file, obstacles, rails)
    obstacles += rails
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
    boxes = [belt.bounding_box() for belt in belts]
    return (min(b[0] for b in boxes), min(b[1] for b in boxes),
            max(b[2] for b in boxes), max(b[3] for b in boxes))


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
