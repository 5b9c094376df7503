"""``conveyor-twin bench clog``: clogging at a bottleneck, the micro simulator against a converged
pymunk reference on the same scenes.

The scene is the default cell's belt and deflector with the gap between the deflector's tip
and the right wall narrowed to G part diameters (the deflector is extended along its own line
until the clear width between its surface and the wall's is G d); sources, sinks, light
barriers and actuators are left out. N of the cell's parts (spacers, d = 10 mm) are released
upstream of the deflector at the belt speed, on a hexagonal lattice of pitch
:data:`RELEASE_PITCH` diameters with every centre moved at random by up to
:data:`RELEASE_JITTER` of a diameter (one random draw per seed, the same positions for both
engines). The belt carries them against the deflector; they slide along it to the gap.

A part has *passed* once its centre is more than a radius beyond the tip of the deflector
(its end cap included). A run is *stopped* when no part passed during the last
:data:`QUIET` s of the window while parts remain upstream: the flow has clogged. Per run the
benchmark also reports the fraction passed, the time of the last passage and the deepest
overlap between two parts (sampled every :data:`SAMPLE` s, as % of a diameter).

The reference is pymunk (Chipmunk2D) built by :func:`conveyor_twin.bench.micro.pymunk_peer`,
the peer of ``bench micro``: same geometry, per-pair friction and restitution, the same belt
drive; here run close to convergence: :data:`PYMUNK_ITERATIONS` solver iterations,
``collision_slop`` :data:`PYMUNK_SLOP` m, step :data:`PYMUNK_STEP` s. Ours runs the cell as
it is (1 ms steps, its own substeps).

The trend from the granular-flow literature: the probability that an arch stops the discharge
of a given amount of grains falls steeply as the opening grows relative to the grain size
(To, Lai and Pak, *Jamming of granular flow in a two-dimensional hopper*: from near one to near
zero over about three to five disc diameters; Janda et al., *Jamming and critical outlet size
in the discharge of a two-dimensional silo*: the chance of passing N grains without a jam
decays exponentially in N, the mean number between jams grows steeply with the outlet;
Zuriguel et al., *Jamming during the discharge of granular matter from a silo*: the same in
three dimensions).

Measured on the shared 2-core machine (load average ~3.5, pymunk 7.3.1), defaults, stopped runs
of 10 (ours / pymunk): 2 d 0 / 6 (passed 100 % / 20 %), 3-6 d 0 / 0 (all passed in both);
``--gaps 2.5``: 0 / 2 (passed 100 % / 60 %). Deepest overlap ours 6.7-14.6 % of a diameter,
pymunk 0.9-1.2 %. 8.9 min wall clock, almost all of it pymunk's; ours 10 s for the 50 runs.
"""

import argparse
import dataclasses
import json
import math
import sys
import time
from typing import Dict, List, Optional, Sequence

import numpy as np

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell, ObstacleKind
from conveyor_twin.micro import MicroSim

DEFAULT_GAPS = (2, 3, 4, 5, 6)      # clear width of the gap [part diameters]
DEFAULT_SEEDS = 10                  # runs per gap (seeds 1..n)
DEFAULT_PARTS = 150
DEFAULT_WINDOW = 5.0                # s of simulated time per run
QUIET = 1.0                         # s without a passage at the end of the window: stopped
SAMPLE = 0.01                       # s between two looks at the positions
RELEASE_PITCH = 1.1                 # lattice pitch of the release [part diameters]
RELEASE_JITTER = 0.04               # largest random move of a released centre [diameters]
RELEASE_MARGIN = 0.002              # m between the release block and the deflector / walls
PYMUNK_ITERATIONS = 150
PYMUNK_SLOP = 1e-4                  # m
PYMUNK_STEP = 2.5e-4                # s


def _deflector(cell: Cell) -> int:
    for index, obstacle in enumerate(cell.obstacles):
        if obstacle.kind == ObstacleKind.DEFLECTOR:
            return index
    raise ValueError(f'cell {cell.settings.name!r} has no deflector')


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    e = b - a
    f = min(1.0, max(0.0, float((p - a) @ e) / float(e @ e)))
    return float(np.hypot(*(p - (a + f * e))))


def clearance(cell: Cell) -> float:
    """Return the clear width between the deflector's tip and the nearest wall [m]."""
    k = _deflector(cell)
    deflector = cell.obstacles[k]
    tip = np.asarray(deflector.points[-1], dtype=float)
    best = math.inf
    for obstacle in cell.obstacles:
        if obstacle.kind != ObstacleKind.WALL:
            continue
        a, b = (np.asarray(q, dtype=float) for q in obstacle.points)
        gap = (_segment_distance(tip, a, b) - 0.5 * obstacle.thickness
               - 0.5 * deflector.thickness)
        best = min(best, gap)
    return best


def gap_cell(gap: float, base: Optional[Cell] = None) -> Cell:
    """Return the default cell (or ``base``) with its gap narrowed to ``gap`` part diameters.

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


def pass_line(cell: Cell) -> float:
    """Return x [m] beyond which a part's centre has passed the deflector's tip."""
    deflector = cell.obstacles[_deflector(cell)]
    tip_x = max(p[0] for p in deflector.points)
    return tip_x + 0.5 * deflector.thickness + cell.part_types[0].radius


def release_positions(cell: Cell, n: int, seed: int) -> np.ndarray:
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


class Watch:
    """Passages, the last one's time and the deepest overlap of one run, sample by sample."""

    def __init__(self, n: int, line: float, radius: float) -> None:
        self.passed = np.zeros(n, dtype=bool)
        self.line = line
        self.radius = radius
        self.last_pass = None
        self.deepest = 0.0

    def look(self, t: float, pts: np.ndarray) -> None:
        now = pts[:, 0] > self.line
        if np.any(now & ~self.passed):
            self.last_pass = t
        self.passed |= now
        self.deepest = max(self.deepest, deepest_overlap(pts, self.radius))

    def result(self, window: float, wall_s: float) -> Dict:
        n = self.passed.size
        passed = int(self.passed.sum())
        quiet = self.last_pass is None or self.last_pass <= window - quiet_time(window)
        d = 2.0 * self.radius
        return {'passed': passed, 'fraction_passed': passed / n if n else 0.0,
                'stopped': bool(quiet and passed < n),
                'last_pass_s': self.last_pass,
                'max_overlap_pct': 100.0 * self.deepest / d, 'wall_s': wall_s}


def quiet_time(window: float) -> float:
    """Return the span at the end of a ``window`` [s] without passages that means stopped."""
    return min(QUIET, window)


def _samples(window: float, dt: float):
    """Yield (steps to take, time after them) for samples every :data:`SAMPLE` s."""
    per = max(1, int(round(SAMPLE / dt)))
    total = int(round(window / dt))
    done = 0
    while done < total:
        k = min(per, total - done)
        done += k
        yield k, done * dt


def run_ours(cell: Cell, positions: np.ndarray, window: float, seed: int) -> Dict:
    """Run our micro simulator on the scene for ``window`` s; return the run's figures."""
    t0 = time.perf_counter()
    part = cell.part_types[0]
    cell = dataclasses.replace(cell, micro=dataclasses.replace(
        cell.micro, capacity=max(len(positions), 1)))
    sim = MicroSim(cell, seed=seed)
    sim.spawn(0, positions[:, 0], positions[:, 1], 0.0, vx=cell.belts[0].speed)
    watch = Watch(len(positions), pass_line(cell), part.radius)
    for k, t in _samples(window, sim.dt):
        sim.step(k)
        view = sim.parts_view()
        watch.look(t, np.stack([view.x, view.y], axis=1))
        if watch.passed.all():
            break
    return watch.result(window, time.perf_counter() - t0)


def run_pymunk(cell: Cell, positions: np.ndarray, window: float, *,
               iterations: int = PYMUNK_ITERATIONS, slop: float = PYMUNK_SLOP,
               step: float = PYMUNK_STEP) -> Dict:
    """Run the pymunk reference on the scene for ``window`` s; return the run's figures."""
    import pymunk.batch

    from conveyor_twin.bench.micro import pymunk_peer

    t0 = time.perf_counter()
    space, drive, dt = pymunk_peer(cell, positions, iterations=iterations, slop=slop,
                                   step=step)
    ids_buf = pymunk.batch.Buffer()
    pymunk.batch.get_space_bodies(space, pymunk.batch.BodyFields.BODY_ID, ids_buf)
    ids = np.frombuffer(ids_buf.int_buf(), dtype=np.uintp)
    dynamic = ids != space.static_body.id
    buf = pymunk.batch.Buffer()
    watch = Watch(len(positions), pass_line(cell), cell.part_types[0].radius)
    for k, t in _samples(window, dt):
        for _ in range(k):
            drive()
            space.step(dt)
        buf.clear()
        pymunk.batch.get_space_bodies(space, pymunk.batch.BodyFields.POSITION, buf)
        pts = np.frombuffer(buf.float_buf(), dtype=np.float64).reshape(-1, 2)[dynamic]
        watch.look(t, pts)
        if watch.passed.all():
            break
    return watch.result(window, time.perf_counter() - t0)


def summary(runs: Sequence[Dict]) -> Dict:
    """Return the ensemble figures of one engine at one gap."""
    stopped = sum(r['stopped'] for r in runs)
    n = len(runs)
    frac = np.array([r['fraction_passed'] for r in runs])
    return {'runs': n, 'stopped': stopped, 'clog_probability': stopped / n if n else None,
            'fraction_passed_mean': float(frac.mean()) if n else None,
            'fraction_passed_min': float(frac.min()) if n else None,
            'fraction_passed_max': float(frac.max()) if n else None,
            'max_overlap_pct': max((r['max_overlap_pct'] for r in runs), default=None),
            'wall_s': float(sum(r['wall_s'] for r in runs))}


def wilson(k: int, n: int, z: float = 1.96) -> tuple:
    """Return the Wilson score interval of ``k`` successes in ``n`` trials (95 % by default)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def run(gaps: Sequence[float], seeds: int, parts: int, window: float, *,
        pymunk: bool = True, iterations: int = PYMUNK_ITERATIONS, slop: float = PYMUNK_SLOP,
        step: float = PYMUNK_STEP, on_gap=None) -> Dict:
    """Run the benchmark; return its report.

    ``on_gap(key, entry)`` is called after each gap with its runs and summaries.
    """
    report: Dict = {'parts': parts, 'seeds': seeds, 'window_s': window,
                    'quiet_s': quiet_time(window),
                    'sample_s': SAMPLE,
                    'pymunk': {'iterations': iterations, 'slop_m': slop, 'step_s': step}
                    if pymunk else None, 'gaps': {}}
    base = load_cell(None)
    report['part_diameter_m'] = 2.0 * base.part_types[0].radius
    report['default_gap_m'] = clearance(base)
    for gap in gaps:
        cell = gap_cell(gap, base)
        entry: Dict = {'gap_m': clearance(cell), 'pass_line_x_m': pass_line(cell),
                       'ours': [], 'pymunk': []}
        for seed in range(1, seeds + 1):
            pts = release_positions(cell, parts, seed)
            entry['ours'].append(run_ours(cell, pts, window, seed))
            if pymunk:
                entry['pymunk'].append(run_pymunk(cell, pts, window, iterations=iterations,
                                                  slop=slop, step=step))
        entry['summary'] = {'ours': summary(entry['ours'])}
        if pymunk:
            entry['summary']['pymunk'] = summary(entry['pymunk'])
        report['gaps'][f'{gap:g}'] = entry
        if on_gap:
            on_gap(f'{gap:g}', entry)
    return report


def _line(gap: str, entry: Dict) -> str:
    parts = [f'G = {gap:>3} d ({entry["gap_m"] * 1e3:5.1f} mm)']
    for name in ('ours', 'pymunk'):
        s = entry['summary'].get(name)
        if s is None:
            continue
        lo, hi = wilson(s['stopped'], s['runs'])
        parts.append(f'{name}: stopped {s["stopped"]}/{s["runs"]} = '
                     f'{s["clog_probability"]:.2f} [{lo:.2f}, {hi:.2f}], passed '
                     f'{s["fraction_passed_mean"]:.0%} ({s["fraction_passed_min"]:.0%}-'
                     f'{s["fraction_passed_max"]:.0%}), overlap <= '
                     f'{s["max_overlap_pct"]:.1f} % d, {s["wall_s"]:.1f} s')
    return ' | '.join(parts)


LITERATURE = ('literature (To, Lai and Pak; Janda et al.; Zuriguel et al.): the probability of '
              'a clog falls steeply as the opening grows, in 2D hoppers from near 1 to near 0 '
              'over a narrow range of openings of a few diameters')


def main(argv: List[str]) -> int:
    """Run the benchmark; print a table or (``--json``) one JSON object."""
    parser = argparse.ArgumentParser(prog='conveyor-twin bench clog', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--gaps', default=','.join(map(str, DEFAULT_GAPS)),
                        help='comma-separated gap widths [part diameters]')
    parser.add_argument('--seeds', type=int, default=DEFAULT_SEEDS, help='runs per gap')
    parser.add_argument('--parts', type=int, default=DEFAULT_PARTS, help='parts per run')
    parser.add_argument('--window', type=float, default=DEFAULT_WINDOW,
                        help='simulated time per run [s]')
    parser.add_argument('--skip-pymunk', action='store_true', help='run ours only')
    parser.add_argument('--pymunk-iterations', type=int, default=PYMUNK_ITERATIONS)
    parser.add_argument('--pymunk-slop', type=float, default=PYMUNK_SLOP, help='[m]')
    parser.add_argument('--pymunk-step', type=float, default=PYMUNK_STEP, help='[s]')
    args = parser.parse_args(argv)
    gaps = [float(g) for g in args.gaps.split(',') if g]
    if args.seeds < 1 or args.parts < 1 or args.window <= 0.0 or not gaps or min(gaps) <= 0:
        parser.error('--gaps positive, --seeds and --parts at least 1, --window positive')
    if not args.json:
        print(f'{args.parts} parts, {args.seeds} seeds per gap, {args.window:g} s window; '
              f'stopped: no passage in the last {quiet_time(args.window):g} s with parts '
              'upstream (95 % Wilson interval)')
        if not args.skip_pymunk:
            print(f'pymunk: {args.pymunk_iterations} iterations, slop {args.pymunk_slop:g} m, '
                  f'step {args.pymunk_step:g} s', flush=True)
    t0 = time.perf_counter()
    report = run(gaps, args.seeds, args.parts, args.window, pymunk=not args.skip_pymunk,
                 iterations=args.pymunk_iterations, slop=args.pymunk_slop,
                 step=args.pymunk_step,
                 on_gap=None if args.json else lambda key, e: print(_line(key, e), flush=True))
    report['wall_s'] = time.perf_counter() - t0
    report['literature'] = LITERATURE
    if args.json:
        print(json.dumps(report))
        return 0
    print(LITERATURE)
    print(f'wall time {report["wall_s"]:.0f} s (load average {_load()})')
    return 0


def _load() -> str:
    try:
        with open('/proc/loadavg', encoding='ascii') as f:
            return f.read().split()[0]
    except OSError:
        return 'unknown'


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
