"""The scenes of ``bench clog``: two bottlenecks on the default cell's belt, their release of
parts, and what one run measures (passages, stop, deepest overlap); the twin's run.

``deflector``: the default cell's 45° deflector, extended along its own line until the clear
width between its tip and the right side wall is G part diameters (an asymmetric opening: an
inclined wall against a straight one). The parts start on a jittered hexagonal lattice just
upstream of the deflector (:func:`lattice_release`).

``funnel``: the deflector removed; two symmetric walls of the deflector's material, each at
:data:`FUNNEL_ANGLE_DEG` to the running direction, run from the side walls to an opening of G
clear diameters on the belt's centre line, its downstream edge where the deflector's tip is
(a two-dimensional hopper whose walls make 30° with the flow). The parts start at random
(random sequential addition) in a block upstream of the funnel (:func:`random_release`).

In both, the parts (the cell's first part type) start at the belt speed; sources, sinks, light
barriers and actuators are left out. The part's contact friction is made constant
(:func:`constant_friction`): its static and sliding coefficients both become their mean (0.215
for the spacer), so the twin's part-part friction is that constant and its part-obstacle
friction the obstacle's coefficient (0.15) at every sliding speed. pymunk's coefficients are
constant, and the peer takes exactly these values per pair; matching the twin's
speed-dependent law (Horváth et al.: static below the transition speed) would instead need a
Python callback per contact and step. Both engines thus model the same friction law.

A part has *passed* once its centre is more than a radius beyond the downstream end of the
bottleneck (:attr:`Scene.pass_line`). A run has *stopped* when no part passed during the last
:data:`QUIET` s of the window while parts remain upstream.
"""

import dataclasses
import hashlib
import math
import time
from typing import Dict, List, Optional, Tuple

import numpy as np

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell, Obstacle, ObstacleKind
from conveyor_twin.micro import MicroSim

SCENES = ('deflector', 'funnel')
QUIET = 1.0                         # s without a passage at the end of the window: stopped
SAMPLE = 0.01                       # s between two looks at the positions
RELEASE_PITCH = 1.1                 # deflector: lattice pitch of the release [part diameters]
RELEASE_JITTER = 0.04               # deflector: largest random move of a centre [diameters]
RELEASE_MARGIN = 0.002              # m between a release block and the walls / bottleneck
FUNNEL_ANGLE_DEG = 30.0             # funnel: angle of each wall to the running direction
RELEASE_PACKING = 0.35              # funnel: area fraction of the random release block
RELEASE_CLEARANCE = 0.02            # funnel: least gap between two released parts [diameters]
FUNNEL_NAMES = ('funnel_left', 'funnel_right')


def constant_friction(cell: Cell) -> Cell:
    """Return ``cell`` with its first part type's contact friction constant.

    ``friction_static`` and ``friction_sliding`` both become their mean, the value the pymunk
    peer takes for a part pair; with equal coefficients the twin's part-obstacle friction is the
    obstacle's ``friction`` at every sliding speed, the peer's value for that pair.
    """
    part = cell.part_types[0]
    mu = 0.5 * (part.friction_static + part.friction_sliding)
    part = dataclasses.replace(part, friction_static=mu, friction_sliding=mu)
    return dataclasses.replace(cell, part_types=(part,) + tuple(cell.part_types[1:]))


def _deflector(cell: Cell) -> int:
    for index, obstacle in enumerate(cell.obstacles):
        if obstacle.kind == ObstacleKind.DEFLECTOR:
            return index
    raise ValueError(f'cell {cell.settings.name!r} has no deflector')


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    e = b - a
    f = min(1.0, max(0.0, float((p - a) @ e) / float(e @ e)))
    return float(np.hypot(*(p - (a + f * e))))


def segments_distance(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> float:
    """Return the least distance between segments ab and cd [m] (0 if they cross)."""
    def cross(o, p, q) -> float:
        return float((p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0]))
    if (cross(a, b, c) * cross(a, b, d) < 0.0) and (cross(c, d, a) * cross(c, d, b) < 0.0):
        return 0.0
    return min(_segment_distance(a, c, d), _segment_distance(b, c, d),
               _segment_distance(c, a, b), _segment_distance(d, a, b))


def _ends(obstacle: Obstacle) -> Tuple[np.ndarray, np.ndarray]:
    a, b = obstacle.points
    return np.asarray(a, dtype=float), np.asarray(b, dtype=float)


def clearance(cell: Cell) -> float:
    """Return the clear width between the deflector's tip and the nearest wall [m]."""
    deflector = cell.obstacles[_deflector(cell)]
    tip = np.asarray(deflector.points[-1], dtype=float)
    best = math.inf
    for obstacle in cell.obstacles:
        if obstacle.kind != ObstacleKind.WALL:
            continue
        a, b = _ends(obstacle)
        gap = (_segment_distance(tip, a, b) - 0.5 * obstacle.thickness
               - 0.5 * deflector.thickness)
        best = min(best, gap)
    return best


def funnel_clearance(cell: Cell) -> float:
    """Return the clear width between the two funnel walls' surfaces [m]."""
    left, right = (next(o for o in cell.obstacles if o.name == name) for name in FUNNEL_NAMES)
    return (segments_distance(*_ends(left), *_ends(right))
            - 0.5 * (left.thickness + right.thickness))


def gap_cell(gap: float, base: Optional[Cell] = None) -> Cell:
    """Return the default cell (or ``base``) with its deflector gap narrowed to ``gap`` diameters.

    The deflector's downstream end moves along the deflector's line until the clear width
    between it and the nearest wall is ``gap`` diameters of the first part type. Sources,
    sinks, light barriers and actuators are removed: the benchmark places the parts itself.
    """
    cell = load_cell(None) if base is None else base
    k = _deflector(cell)
    deflector = cell.obstacles[k]
    (ax, ay), (bx, by) = deflector.points
    u = np.array([bx - ax, by - ay]) / math.hypot(bx - ax, by - ay)
    want = gap * 2.0 * cell.part_types[0].radius
    if not 0.0 < want <= clearance(cell):
        raise ValueError(f'gap {gap} d is not positive or wider than the cell\'s '
                         f'{clearance(cell):.3f} m')

    def moved(s: float) -> Cell:
        points = ((ax, ay), (bx + s * u[0], by + s * u[1]))
        obstacles = list(cell.obstacles)
        obstacles[k] = dataclasses.replace(deflector, points=points)
        return dataclasses.replace(cell, obstacles=tuple(obstacles))

    # march toward the wall in steps of a tenth of the wanted width, then bisect (the
    # clearance falls while the tip approaches the wall and rises again beyond it)
    lo, hi = 0.0, 0.1 * want
    while clearance(moved(hi)) > want:
        lo, hi = hi, hi + 0.1 * want
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if clearance(moved(mid)) > want:
            lo = mid
        else:
            hi = mid
    out = moved(0.5 * (lo + hi))
    return dataclasses.replace(out, sources=(), sinks=(), light_barriers=(), actuators=())


def funnel_cell(gap: float, base: Optional[Cell] = None) -> Cell:
    """Return the default cell (or ``base``) with a symmetric funnel opening to ``gap`` diameters.

    The deflector is replaced by two walls of its material and thickness, each at
    :data:`FUNNEL_ANGLE_DEG` to the belt's running direction (+x), from the side walls' centre
    lines (y = +-0.255 m) to the opening, whose downstream edge is at the deflector's tip x.
    """
    cell = load_cell(None) if base is None else base
    k = _deflector(cell)
    deflector = cell.obstacles[k]
    half_wall = 0.5 * deflector.thickness
    d = 2.0 * cell.part_types[0].radius
    side = max(abs(p[1]) for o in cell.obstacles if o.kind == ObstacleKind.WALL
               for p in o.points)
    end_y = 0.5 * gap * d + half_wall
    if not 0.0 < gap * d < 2.0 * (side - half_wall):
        raise ValueError(f'funnel gap {gap} d is not positive or not narrower than the belt '
                         f'({2.0 * (side - half_wall):.3f} m between the side walls)')
    tip_x = max(p[0] for p in deflector.points)
    run = (side - end_y) / math.tan(math.radians(FUNNEL_ANGLE_DEG))
    walls = tuple(dataclasses.replace(deflector, name=name, kind=ObstacleKind.WALL,
                                      points=((tip_x - run, s * side), (tip_x, s * end_y)))
                  for name, s in zip(FUNNEL_NAMES, (1.0, -1.0)))
    obstacles = cell.obstacles[:k] + walls + cell.obstacles[k + 1:]
    return dataclasses.replace(cell, obstacles=obstacles, sources=(), sinks=(),
                               light_barriers=(), actuators=())


def lattice_release(cell: Cell, n: int, seed: int) -> np.ndarray:
    """Return (n, 2) centres [m] upstream of the deflector, a jittered hexagonal lattice.

    Rows across the belt, from just upstream of the deflector's upstream end against the
    belt direction; the pitch (:data:`RELEASE_PITCH`) less twice the jitter
    (:data:`RELEASE_JITTER`) is still more than a diameter, so no two parts overlap.
    """
    r = cell.part_types[0].radius
    d = 2.0 * r
    pitch = RELEASE_PITCH * d
    jitter = RELEASE_JITTER * d
    deflector = cell.obstacles[_deflector(cell)]
    x_front = (min(p[0] for p in deflector.points) - 0.5 * deflector.thickness - r - jitter
               - RELEASE_MARGIN)
    y_max = 0.5 * cell.belts[0].width - r - jitter - RELEASE_MARGIN
    pts: List[tuple] = []
    row = 0
    while len(pts) < n:
        x = x_front - row * pitch * math.sqrt(3.0) / 2.0
        if x < r + jitter:
            raise ValueError(f'{n} parts do not fit upstream of the deflector')
        y = -y_max + (0.5 * pitch if row % 2 else 0.0)
        while y <= y_max and len(pts) < n:
            pts.append((x, y))
            y += pitch
        row += 1
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0.0, 2.0 * math.pi, n)
    radius = jitter * np.sqrt(rng.uniform(0.0, 1.0, n))
    return np.array(pts) + np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)


def random_release(cell: Cell, n: int, seed: int) -> np.ndarray:
    """Return (n, 2) centres [m] at random in a block upstream of the funnel.

    Random sequential addition: uniform candidates in a block across the belt (between the
    side walls, :data:`RELEASE_MARGIN` from them) whose depth gives an area fraction of
    :data:`RELEASE_PACKING`; a candidate closer than (1 + :data:`RELEASE_CLEARANCE`) d to an
    accepted centre is drawn again.
    """
    r = cell.part_types[0].radius
    d = 2.0 * r
    funnel_x = min(p[0] for o in cell.obstacles if o.name in FUNNEL_NAMES for p in o.points)
    y_max = 0.5 * cell.belts[0].width - r - RELEASE_MARGIN
    depth = n * math.pi * r * r / (RELEASE_PACKING * 2.0 * (y_max + r))
    x_hi = funnel_x - r - RELEASE_MARGIN
    x_lo = x_hi - depth
    if x_lo < r:
        raise ValueError(f'{n} parts do not fit upstream of the funnel')
    rng = np.random.default_rng(seed)
    pts = np.empty((n, 2))
    least = (1.0 + RELEASE_CLEARANCE) * d
    count = 0
    tries = 0
    while count < n:
        tries += 1
        if tries > 1000 * n:
            raise ValueError(f'{n} parts do not fit in the release block')
        p = (rng.uniform(x_lo, x_hi), rng.uniform(-y_max, y_max))
        if count and np.min(np.hypot(pts[:count, 0] - p[0], pts[:count, 1] - p[1])) < least:
            continue
        pts[count] = p
        count += 1
    return pts


@dataclasses.dataclass(frozen=True)
class Scene:
    """One bottleneck scene at one gap: the cell, its clear width [m] and pass line x [m]."""

    name: str
    gap: float
    cell: Cell
    clear_width: float
    pass_line: float

    def release(self, n: int, seed: int) -> np.ndarray:
        """Return the (n, 2) start centres [m] of seed ``seed`` (the same for both engines)."""
        if self.name == 'deflector':
            return lattice_release(self.cell, n, seed)
        return random_release(self.cell, n, seed)

    def parameters(self) -> Dict:
        """Return what a run of either engine depends on, as plain JSON data."""
        cell = self.cell
        part = cell.part_types[0]
        belt = cell.belts[0]
        return {
            'scene': self.name, 'gap_d': self.gap, 'clear_width_m': self.clear_width,
            'pass_line_x_m': self.pass_line, 'gravity': cell.settings.gravity,
            'belt': {'speed': belt.speed, 'friction': belt.friction, 'width': belt.width},
            'part': {f: getattr(part, f) for f in (
                'radius', 'mass', 'inertia', 'restitution', 'friction_static',
                'friction_sliding')},
            'obstacles': [{'name': o.name, 'kind': str(o.kind.value),
                           'points': [list(map(float, p)) for p in o.points],
                           'thickness': o.thickness, 'radius': o.radius,
                           'restitution': o.restitution, 'friction': o.friction}
                          for o in cell.obstacles],
            'quiet_s': QUIET, 'sample_s': SAMPLE}


def build_scene(name: str, gap: float, base: Optional[Cell] = None) -> Scene:
    """Return scene ``name`` (one of :data:`SCENES`) with a gap of ``gap`` part diameters.

    The part's contact friction is made constant (:func:`constant_friction`).
    """
    base = constant_friction(load_cell(None) if base is None else base)
    r = base.part_types[0].radius
    if name == 'deflector':
        cell = gap_cell(gap, base)
        deflector = cell.obstacles[_deflector(cell)]
        tip_x = max(p[0] for p in deflector.points)
        return Scene(name, gap, cell, clearance(cell), tip_x + 0.5 * deflector.thickness + r)
    if name == 'funnel':
        cell = funnel_cell(gap, base)
        walls = [o for o in cell.obstacles if o.name in FUNNEL_NAMES]
        tip_x = max(p[0] for o in walls for p in o.points)
        return Scene(name, gap, cell, funnel_clearance(cell),
                     tip_x + 0.5 * walls[0].thickness + r)
    raise ValueError(f'scene {name!r} is not one of {", ".join(SCENES)}')


def positions_digest(pts: np.ndarray) -> str:
    """Return a short digest of start positions (to tell a stale reference run)."""
    return hashlib.sha256(np.ascontiguousarray(pts, dtype='<f8').tobytes()).hexdigest()[:16]


def deepest_overlap(pts: np.ndarray, radius: float) -> float:
    """Return the deepest overlap of two discs of ``radius`` centred at ``pts`` [m] (exact)."""
    if len(pts) < 2:
        return 0.0
    p = pts[np.argsort(pts[:, 0])]
    d = 2.0 * radius
    deepest = 0.0
    for shift in range(1, len(p)):
        dx = p[shift:, 0] - p[:-shift, 0]
        near = dx < d
        if not near.any():
            break   # sorted by x: every larger shift is at least as far apart
        gap = np.hypot(dx[near], p[shift:, 1][near] - p[:-shift, 1][near])
        deepest = max(deepest, float(d - gap.min()))
    return deepest


def quiet_time(window: float) -> float:
    """Return the span at the end of a ``window`` [s] without passages that means stopped."""
    return min(QUIET, window)


class Watch:
    """Passages, the last one's time and the deepest overlap of one run, sample by sample."""

    def __init__(self, n: int, line: float, radius: float) -> None:
        self.passed = np.zeros(n, dtype=bool)
        self.line = line
        self.radius = radius
        self.last_pass = None
        self.deepest = 0.0

    def look(self, t: float, pts: np.ndarray) -> None:
        """Take the positions ``pts`` ((n, 2) [m]) at time ``t`` [s]."""
        now = pts[:, 0] > self.line
        if np.any(now & ~self.passed):
            self.last_pass = t
        self.passed |= now
        self.deepest = max(self.deepest, deepest_overlap(pts, self.radius))

    def result(self, window: float, wall_s: float) -> Dict:
        """Return the run's figures after a ``window`` [s] that took ``wall_s`` [s]."""
        n = self.passed.size
        passed = int(self.passed.sum())
        quiet = self.last_pass is None or self.last_pass <= window - quiet_time(window)
        d = 2.0 * self.radius
        return {'passed': passed, 'fraction_passed': passed / n if n else 0.0,
                'stopped': bool(quiet and passed < n),
                'last_pass_s': self.last_pass,
                'max_overlap_pct': 100.0 * self.deepest / d, 'wall_s': wall_s}


def samples(window: float, dt: float):
    """Yield (steps to take, time after them) for samples every :data:`SAMPLE` s."""
    per = max(1, int(round(SAMPLE / dt)))
    total = int(round(window / dt))
    done = 0
    while done < total:
        k = min(per, total - done)
        done += k
        yield k, done * dt


def run_twin(scene: Scene, positions: np.ndarray, window: float, seed: int,
             micro: Optional[Dict] = None) -> Dict:
    """Run the twin's micro simulator on ``scene`` for ``window`` s; return the run's figures.

    ``micro``: settings of the cell's ``micro`` section to change (e.g. the sweep budget).
    """
    t0 = time.perf_counter()
    cell = scene.cell
    cell = dataclasses.replace(cell, micro=dataclasses.replace(
        cell.micro, capacity=max(len(positions), 1), **(micro or {})))
    sim = MicroSim(cell, seed=seed)
    sim.spawn(0, positions[:, 0], positions[:, 1], 0.0, vx=cell.belts[0].speed)
    watch = Watch(len(positions), scene.pass_line, cell.part_types[0].radius)
    for k, t in samples(window, sim.dt):
        sim.step(k)
        view = sim.parts_view()
        watch.look(t, np.stack([view.x, view.y], axis=1))
        if watch.passed.all():
            break
    return watch.result(window, time.perf_counter() - t0)
