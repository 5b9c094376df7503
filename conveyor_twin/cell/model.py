"""The cell description as validated, frozen dataclasses in SI units (frame ``cell``, REP-103).

x runs along the main conveying direction, y to the left, z up. Every length is in m, every
time in s, every angle in rad, masses in kg, inertias in kg m^2. The loader in
:mod:`conveyor_twin.cell.loader` is the only way these are built from a file; it guarantees
the invariants documented on each class.
"""

from dataclasses import dataclass, field
from enum import Enum
import math
from typing import Optional, Tuple

from conveyor_twin.cell.curves import (
    BeltCurve, CONTAINS_TOLERANCE, curve_bounding_box, curve_contains, curve_outline, Point,
    Rect,
)


class Mode(str, Enum):
    """A mode of the cell model: an Enum whose members are also their string values.

    ``Mode`` members compare, hash, print and format as their value (``ZonePolicy.AUTO ==
    'auto'``, ``f'{ZonePolicy.AUTO}' == 'auto'``), so a cell file's strings and the members are
    interchangeable; the kernels take ints derived from them.
    """

    __str__ = str.__str__
    __format__ = str.__format__


@dataclass(frozen=True)
class Settings:
    """Cell-wide settings.

    :param name: cell name, used in summaries and recordings.
    :param frame_id: frame of every published pose.
    :param step: simulation step [s]; 1e-3 by default.
    :param gravity: gravitational acceleration [m/s^2] (normal force on the belt).
    :param seed: default random seed for sources.
    """

    name: str
    frame_id: str = 'cell'
    step: float = 1e-3
    gravity: float = 9.81
    seed: int = 0


@dataclass(frozen=True)
class Belt:
    """A belt: straight (a rectangle along ``start``-``end`` of ``width``) or curved.

    A curved belt (``curve`` set) is the annular sector of :class:`BeltCurve`; its ``start`` and
    ``end`` are the centre-line points at the start and end angles, ``width`` is
    ``outer_radius - inner_radius`` and ``speed`` is the surface speed on the centre line. Use
    the helpers :meth:`contains`, :meth:`surface_velocity`, :meth:`outline`,
    :meth:`centre_line` and :meth:`bounding_box`, which work for both kinds; ``direction``,
    ``angle`` and ``corners()`` exist for straight belts only.

    :param speed: initial target speed [m/s] along ``direction`` (negative runs backwards).
    :param max_speed: largest admissible |speed| [m/s]; commands beyond it are rejected.
    :param acceleration: largest rate of speed change [m/s^2].
    :param friction: part-belt Coulomb coefficient (drive force bounded by ``friction m g``).
    :param curve: the arc geometry of a curved belt; None for a straight belt.
    """

    name: str
    start: Point
    end: Point
    width: float
    speed: float
    max_speed: float
    acceleration: float
    friction: float
    curve: Optional[BeltCurve] = None

    @property
    def length(self) -> float:
        """Length of the belt [m] (of the centre line for a curved belt)."""
        if self.curve is not None:
            return self.curve.centre_radius * abs(self.curve.sweep)
        return math.hypot(self.end[0] - self.start[0], self.end[1] - self.start[1])

    def _straight_only(self, what: str) -> None:
        if self.curve is not None:
            raise ValueError(f'belt {self.name!r} is curved: it has no {what}; use contains(), '
                             'surface_velocity(), outline() or centre_line()')

    @property
    def direction(self) -> Point:
        """Unit vector of the running direction (straight belts only; ValueError if curved)."""
        self._straight_only('single direction')
        length = self.length
        return ((self.end[0] - self.start[0]) / length, (self.end[1] - self.start[1]) / length)

    @property
    def angle(self) -> float:
        """Heading of the running direction [rad] (straight belts only; ValueError if curved)."""
        self._straight_only('single heading')
        return math.atan2(self.end[1] - self.start[1], self.end[0] - self.start[0])

    def corners(self) -> Tuple[Point, Point, Point, Point]:
        """Return the four corners of the belt surface, counter-clockwise [m] (straight belts
        only; ValueError if curved)."""
        self._straight_only('four corners')
        dx, dy = self.direction
        nx, ny = -dy * self.width / 2, dx * self.width / 2
        (x0, y0), (x1, y1) = self.start, self.end
        return ((x0 - nx, y0 - ny), (x1 - nx, y1 - ny), (x1 + nx, y1 + ny), (x0 + nx, y0 + ny))

    def contains(self, point: Point) -> bool:
        """Return True if ``point`` [m] lies on the belt surface, edges included (within
        :data:`CONTAINS_TOLERANCE`)."""
        if self.curve is not None:
            return curve_contains(self.curve, point)
        tol = CONTAINS_TOLERANCE
        dx, dy = self.direction
        rx, ry = point[0] - self.start[0], point[1] - self.start[1]
        along, across = rx * dx + ry * dy, -rx * dy + ry * dx
        return -tol <= along <= self.length + tol and abs(across) <= 0.5 * self.width + tol

    def surface_velocity(self, point: Point, speed: float) -> Point:
        """Return the surface velocity [m/s] at ``point`` [m] when the belt runs at ``speed``
        [m/s]: ``speed * direction`` (straight), or the rigid rotation omega x r about the
        centre with omega = direction * speed / centre_radius [rad/s] (curved)."""
        c = self.curve
        if c is None:
            dx, dy = self.direction
            return (speed * dx, speed * dy)
        omega = c.direction * speed / c.centre_radius
        return (-omega * (point[1] - c.centre[1]), omega * (point[0] - c.centre[0]))

    def outline(self, max_chord_error: float = 1e-4) -> Tuple[Point, ...]:
        """Return the surface outline as a closed polygon, counter-clockwise, first point not
        repeated [m]. A curved belt's arcs are chords within ``max_chord_error`` [m] of the
        arcs (a full-turn belt gives a keyhole polygon: outer circle, then inner circle back)."""
        if self.curve is not None:
            return curve_outline(self.curve, max_chord_error)
        return self.corners()

    def centre_line(self, n: int) -> Tuple[Point, ...]:
        """Return ``n`` >= 2 points evenly spaced along the centre line from ``start`` to
        ``end`` [m]."""
        if n < 2:
            raise ValueError(f'belt {self.name!r}: centre_line needs n >= 2 points, got {n}')
        c = self.curve
        if c is None:
            (x0, y0), (x1, y1) = self.start, self.end
            return tuple((x0 + (x1 - x0) * i / (n - 1), y0 + (y1 - y0) * i / (n - 1))
                         for i in range(n))
        sweep = c.sweep
        return tuple(c.point(c.centre_radius, c.start_angle + sweep * i / (n - 1))
                     for i in range(n))

    def bounding_box(self) -> Rect:
        """Return the axis-aligned bounding rectangle of the surface [m] (exact for both
        kinds: the corners, plus the outer arc's extreme points inside a curve's sweep)."""
        if self.curve is not None:
            return curve_bounding_box(self.curve)
        corners = self.corners()
        xs, ys = [p[0] for p in corners], [p[1] for p in corners]
        return (min(xs), min(ys), max(xs), max(ys))


class ObstacleKind(Mode):
    """Kind of a static obstacle (see :class:`Obstacle`)."""

    WALL = 'wall'
    DEFLECTOR = 'deflector'
    PEG = 'peg'
    POLYGON = 'polygon'


OBSTACLE_KINDS = tuple(k.value for k in ObstacleKind)


@dataclass(frozen=True)
class Obstacle:
    """A fixed obstacle (infinite mass).

    ``wall`` and ``deflector``: a polyline through ``points`` of full thickness ``thickness``
    (a capsule chain of radius ``thickness/2``). ``peg``: a round peg at ``points[0]`` of
    ``radius``. ``polygon``: a convex polygon, ``points`` counter-clockwise.

    :param restitution: coefficient of restitution against parts, 0..1.
    :param friction: Coulomb coefficient against parts.
    """

    name: str
    kind: ObstacleKind
    points: Tuple[Point, ...]
    thickness: float = 0.0
    radius: float = 0.0
    restitution: float = 0.3
    friction: float = 0.2


PART_SHAPES = ('disc', 'box')


@dataclass(frozen=True)
class PartType:
    """A kind of part. Its index in :attr:`Cell.part_types` is the ``part_type`` on the wire.

    :param shape: ``disc`` (standing cylinder of ``radius``) or ``box`` (``length`` x ``width``,
        ``length`` along the body x axis).
    :param height: height above the belt [m] (light barriers see a part if beam height < height).
    :param mass: [kg]. :param inertia: about the vertical axis [kg m^2].
    :param restitution: part-part coefficient of restitution (the pair uses the mean).
    :param friction_static: impact friction coefficient at zero tangential speed (Horváth et al.).
    :param friction_sliding: impact friction coefficient above ``friction_transition_speed``.
    :param friction_transition_speed: tangential speed [m/s] where sliding friction is reached.
    """

    name: str
    shape: str
    radius: float
    length: float
    width: float
    height: float
    mass: float
    inertia: float
    restitution: float
    friction_static: float
    friction_sliding: float
    friction_transition_speed: float

    @property
    def bounding_radius(self) -> float:
        """Radius of the smallest circle around the centre that holds the footprint [m]."""
        if self.shape == 'disc':
            return self.radius
        return 0.5 * math.hypot(self.length, self.width)

    @property
    def footprint_area(self) -> float:
        """Area of the footprint on the belt [m^2]."""
        if self.shape == 'disc':
            return math.pi * self.radius ** 2
        return self.length * self.width


SOURCE_PATTERNS = ('uniform', 'poisson', 'burst')


@dataclass(frozen=True)
class Source:
    """Where parts enter: spawned at random poses in ``region``, never overlapping anything.

    :param rate: mean rate [parts/s].
    :param pattern: ``uniform`` (every 1/rate s), ``poisson`` (exponential gaps) or ``burst``
        (``burst_size`` parts every burst_size/rate s).
    :param velocity: initial velocity [m/s]; ``None`` means the local belt surface velocity.
    :param yaw: initial yaw [rad]; ``None`` means uniformly random.
    :param start_time: first spawn not before this sim time [s].
    :param max_parts: stop after this many parts; 0 means unlimited.
    :param seed: stream offset, combined with the run's seed.
    """

    name: str
    part_type: str
    region: Rect
    rate: float
    pattern: str = 'uniform'
    burst_size: int = 1
    velocity: Optional[Point] = None
    yaw: Optional[float] = None
    start_time: float = 0.0
    max_parts: int = 0
    seed: int = 0


@dataclass(frozen=True)
class Sink:
    """Parts whose centre enters ``region`` leave the cell and are counted."""

    name: str
    region: Rect


@dataclass(frozen=True)
class LightBarrier:
    """A light beam from ``start`` to ``end`` at ``height`` above the belt [m].

    It is blocked while any part taller than ``height`` intersects the beam segment.
    """

    name: str
    start: Point
    end: Point
    height: float


ACTUATOR_KINDS = ('pusher', 'stopper', 'diverter', 'transfer')


@dataclass(frozen=True)
class Actuator:
    """A kinematic actuator moving toward its commanded position at ``max_speed``.

    ``pusher``: a rectangular paddle (``length`` along ``axis``, ``width`` across) whose centre is
    at ``base + position * axis``; position in m.
    ``stopper``: a pop-up blade, footprint ``length`` along ``axis`` by ``width``, centred at
    ``base``; position is its lift [m]; it blocks parts while lifted at least ``engage_height``.
    ``diverter``: an arm of ``length`` and thickness ``width`` rotating about the pivot ``base``;
    at position θ [rad] it points along ``axis`` rotated by θ.
    ``transfer``: a lifting roller or belt transfer unit, footprint ``length`` along ``axis``
    (the direction it carries parts) by ``width``, centred at ``base``; position is its lift
    [m]. While lifted at least ``engage_height`` the surface under its footprint is its own
    (velocity ``surface_speed * axis``, Coulomb coefficient ``friction``), below that the belt
    beneath it; it has no collision shape.

    :param position_range: admissible (min, max) position; commands outside are rejected.
    :param max_speed: [m/s] or [rad/s]. :param initial_position: position at reset.
    :param engage_height: stopper and transfer: lift [m] from which it acts on parts.
    :param friction: Coulomb coefficient against parts (transfer: part-roller).
    :param surface_speed: transfer only: carrying speed along ``axis`` [m/s]; 0 otherwise.
    :param force_limit: largest force the actuator exerts on parts [N] (a diverter: at its
        contact points); beyond it the actuator stalls. ``math.inf``: unlimited.
    """

    name: str
    kind: str
    base: Point
    axis: Point
    length: float
    width: float
    position_range: Tuple[float, float]
    max_speed: float
    initial_position: float
    engage_height: float = 0.0
    restitution: float = 0.2
    friction: float = 0.2
    surface_speed: float = 0.0
    force_limit: float = math.inf

    @property
    def is_rotary(self) -> bool:
        """True if the position is an angle [rad]."""
        return self.kind == 'diverter'


class ZonePolicy(Mode):
    """Scale at which a zone is simulated: always micro, always macro, or switched per tile."""

    MICRO = 'micro'
    MACRO = 'macro'
    AUTO = 'auto'


ZONE_POLICIES = tuple(p.value for p in ZonePolicy)


@dataclass(frozen=True)
class AutoSwitch:
    """Parameters of the ``auto`` policy.

    :param tile: edge of the square tiles that switch independently [m].
    :param to_macro_density: a micro tile turns macro above this density [parts/m^2].
    :param to_micro_density: a macro tile turns micro below this density [parts/m^2].
    :param min_dwell: least time between two switches of a tile [s].
    :param sensor_margin: tiles within this distance of a light barrier or an actuator stay
        micro [m].
    :param free_flow_slip: a micro tile whose parts slip against the local belt velocity by
        less than this fraction of the belt speed on average is free flow and stays micro at
        any density (exact transport between sensor windows); 0 turns the test off [1].
    """

    tile: float = 0.25
    to_macro_density: float = 4000.0
    to_micro_density: float = 1500.0
    min_dwell: float = 0.5
    sensor_margin: float = 0.1
    free_flow_slip: float = 0.0


@dataclass(frozen=True)
class Zone:
    """A rectangular region of the belt surface simulated at one scale.

    :param resolution: cell size of its macro grid [m] (square cells).
    """

    name: str
    policy: ZonePolicy
    region: Rect
    resolution: float
    auto: AutoSwitch = field(default_factory=AutoSwitch)


class ContactModel(Mode):
    """Contact model of the micro simulator: impulses (Hoher et al.) or penalty springs
    (Rideout, Stein)."""

    IMPULSE = 'impulse'
    PENALTY = 'penalty'


CONTACT_MODELS = tuple(c.value for c in ContactModel)

# Impulse model: velocity sweeps per substep (see docs/models.md, Contacts). They stop once no
# contact's increment changes a relative speed by more than CONTACT_TOLERANCE [m/s], or once the
# substep has spent CONTACT_SWEEP_BUDGET contact visits: at least CONTACT_SWEEPS sweeps, at most
# CONTACT_SWEEPS_MAX. The budget converges arches at bottlenecks (a few hundred contacts: their
# clogging statistics agree with a converged reference); the tolerance ends the sweeps of a
# slowly queueing jam after a few, which keeps the realtime step short.
CONTACT_SWEEPS = 16
CONTACT_SWEEPS_MAX = 512
CONTACT_SWEEP_BUDGET = 200_000
CONTACT_TOLERANCE = 3e-4
CONTACT_TOLERANCE_MAX = 0.1      # the largest tolerance a cell may set [m/s]


@dataclass(frozen=True)
class MicroModel:
    """Micro-scale parameters.

    :param contact: ``impulse`` (Hoher et al.) or ``penalty`` (spring-damper, Rideout and Stein).
    :param capacity: preallocated number of part slots.
    :param penetration_slop: penetration left uncorrected [m].
    :param penetration_correction: fraction of the remaining penetration removed per step, 0..1.
    :param penalty_stiffness: contact spring [N/m] (penalty model).
    :param penalty_damping: contact damper [N s/m] (penalty model).
    :param max_travel_fraction: largest displacement per substep as a fraction of the smallest
        part radius; more substeps are taken when parts move faster (no tunnelling).
    :param contact_sweeps: impulse model: least velocity sweeps over the contacts per substep.
    :param contact_sweeps_max: impulse model: most sweeps per substep.
    :param contact_sweep_budget: impulse model: contact visits per substep that buy sweeps
        beyond ``contact_sweeps`` (up to ``contact_sweeps_max``); 0: ``contact_sweeps`` only.
    :param contact_tolerance: impulse model: the sweeps stop once no contact's increment changes
        a relative speed by more than this [m/s] (0: they always run to their limit).
    """

    contact: ContactModel = ContactModel.IMPULSE
    capacity: int = 20000
    penetration_slop: float = 1e-4
    penetration_correction: float = 0.8
    penalty_stiffness: float = 1e5
    penalty_damping: float = 5.0
    max_travel_fraction: float = 0.5
    contact_sweeps: int = CONTACT_SWEEPS
    contact_sweeps_max: int = CONTACT_SWEEPS_MAX
    contact_sweep_budget: int = CONTACT_SWEEP_BUDGET
    contact_tolerance: float = CONTACT_TOLERANCE


class MacroVariant(Mode):
    """Flux of the macro model: capped (Hoher et al.) or with the collision operator
    (Göttlich et al. 2014)."""

    CAPPED = 'capped'
    GOETTLICH = 'goettlich'


class MacroScheme(Mode):
    """Spatial order of the macro finite-volume scheme."""

    UPWIND = 'upwind'
    LIMITED = 'limited'


MACRO_VARIANTS = tuple(v.value for v in MacroVariant)
MACRO_SCHEMES = tuple(s.value for s in MacroScheme)


@dataclass(frozen=True)
class MacroModel:
    """Macro-scale parameters.

    :param variant: ``capped`` (Hoher et al.'s flux) or ``goettlich`` (Göttlich et al. 2014).
    :param scheme: ``upwind`` (first order) or ``limited`` (second order, minmod-limited).
    :param rho_max: maximum density [parts/m^2]; 0 derives hexagonal packing of the first part
        type, ``1 / (2 sqrt(3) R^2)``.
    :param epsilon: strength of the collision operator [m/s].
    :param mollifier_width: support radius of the mollifier [m]; 0 means two grid cells.
    :param cfl: Courant number per substep, (0, 1].
    """

    variant: MacroVariant = MacroVariant.GOETTLICH
    scheme: MacroScheme = MacroScheme.UPWIND
    rho_max: float = 0.0
    epsilon: float = 0.5
    mollifier_width: float = 0.0
    cfl: float = 0.9


@dataclass(frozen=True)
class Cell:
    """A whole validated cell. Names are unique within each list."""

    source_file: str
    settings: Settings
    belts: Tuple[Belt, ...]
    obstacles: Tuple[Obstacle, ...]
    part_types: Tuple[PartType, ...]
    sources: Tuple[Source, ...]
    sinks: Tuple[Sink, ...]
    light_barriers: Tuple[LightBarrier, ...]
    actuators: Tuple[Actuator, ...]
    zones: Tuple[Zone, ...]
    micro: MicroModel
    macro: MacroModel

    def part_type_index(self, name: str) -> int:
        """Return the wire index of the part type ``name``; raise KeyError if unknown."""
        for index, part_type in enumerate(self.part_types):
            if part_type.name == name:
                return index
        raise KeyError(name)

    def belt_index(self, name: str) -> int:
        """Return the index of the belt ``name``; raise KeyError if unknown."""
        for index, belt in enumerate(self.belts):
            if belt.name == name:
                return index
        raise KeyError(name)

    def actuator_index(self, name: str) -> int:
        """Return the index of the actuator ``name``; raise KeyError if unknown."""
        for index, actuator in enumerate(self.actuators):
            if actuator.name == name:
                return index
        raise KeyError(name)

    @property
    def rho_max(self) -> float:
        """Maximum macro density [parts/m^2] (configured or from hexagonal packing)."""
        if self.macro.rho_max > 0.0:
            return self.macro.rho_max
        reference = self.part_types[0]
        radius = math.sqrt(reference.footprint_area / math.pi)
        return 1.0 / (2.0 * math.sqrt(3.0) * radius * radius)

    @property
    def bounds(self) -> Rect:
        """Bounding rectangle of all belts [m]."""
        boxes = [belt.bounding_box() for belt in self.belts]
        return (min(b[0] for b in boxes), min(b[1] for b in boxes),
                max(b[2] for b in boxes), max(b[3] for b in boxes))
