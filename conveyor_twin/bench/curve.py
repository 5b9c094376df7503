"""``conveyor-twin bench curve``: a curved belt's step against a straight belt's of the same area.

Two scenes of the same surface area: a straight belt 0.4 m wide and as long as the curve's
centre line (0.94 m), and a 90 degree curve, radii 0.4 .. 0.8 m; both at 0.1 m/s with friction
0.35. The same number of 20 mm discs stand on the same lattice of each (positions along and
across the belt mapped onto the curve's centre line and radius), moving with the surface, so
no two touch: the step is the surface lookup, the friction drive, the broad phase and the
integration, the case where the surface's share of the step is largest. Rounds alternate the
two scenes (a fresh simulator each, timed over ``--steps`` steps in one compiled call), so load
on the machine hits both alike; the medians of the per-step wall time and their ratio (curve /
straight) are printed.
"""

import argparse
import json
import math
import statistics
import time
from typing import Dict, List, Tuple

import numpy as np

from conveyor_twin.cell.loader import load_cell_text
from conveyor_twin.cell.model import Cell
from conveyor_twin.micro import MicroSim

WIDTH = 0.4           # m
INNER = 0.4           # m, the curve's inner radius
SPEED = 0.1           # m/s
PART_RADIUS = 0.01    # m
DEFAULT_PARTS = 300
DEFAULT_STEPS = 1000
DEFAULT_ROUNDS = 7
FILLED = 0.75         # of the length holding parts at the start (they stay on the belt)

_PART = f'''part_types:
  - {{name: disc, shape: disc, radius: {PART_RADIUS}, height: 0.02, mass: 0.01}}
'''


def centre_radius() -> float:
    """Radius of the curve's centre line [m]."""
    return INNER + 0.5 * WIDTH


def length() -> float:
    """Length of the straight belt [m]: the curve's centre line, so the areas are equal."""
    return 0.5 * math.pi * centre_radius()


def scene(curved: bool, parts: int) -> Cell:
    """Return the straight or the curved scene's cell (capacity for ``parts``)."""
    head = f'cell: {{name: bench_curve, step: 0.001, seed: 1}}\nmicro: {{capacity: {parts}}}\n'
    drive = f'speed: {SPEED}, max_speed: 1.0, acceleration: 1.0, friction: 0.35'
    if curved:
        belt = (f'  - {{name: belt, curve: {{centre: [0.0, 0.0], inner_radius: {INNER}, '
                f'outer_radius: {INNER + WIDTH}, start_angle: -90, end_angle: 0, '
                f'direction: ccw}}, {drive}}}\n')
    else:
        belt = (f'  - {{name: belt, start: [0.0, 0.0], end: [{length()!r}, 0.0], '
                f'width: {WIDTH}, {drive}}}\n')
    return load_cell_text(head + 'belts:\n' + belt + _PART, '<bench curve>')


def lattice(parts: int) -> Tuple[np.ndarray, np.ndarray]:
    """Return (along, across) [m] of ``parts`` lattice points on the belt's first part."""
    margin = 2.0 * PART_RADIUS
    span_u = FILLED * length() - margin
    span_w = WIDTH - 2.0 * margin
    gap = 2.2 * PART_RADIUS
    # on the curve the innermost row's spacing along shrinks by its radius / the centre's
    shrink = (INNER + margin) / centre_radius()
    rows = int(span_w / gap)
    most = rows * int(span_u * shrink / gap)
    if parts > most:
        raise ValueError(f'bench curve: --parts {parts}, at most {most} fit apart on the curve')
    cols = math.ceil(parts / rows)
    pitch_u, pitch_w = span_u / cols, span_w / rows
    k = np.arange(parts)
    along = margin + (k // rows + 0.5) * pitch_u
    across = (k % rows + 0.5) * pitch_w - 0.5 * span_w
    return along, across


def populated(curved: bool, parts: int) -> MicroSim:
    """Return a simulator of the scene with ``parts`` discs moving with the surface."""
    sim = MicroSim(scene(curved, parts), seed=1)
    along, across = lattice(parts)
    if not curved:
        sim.spawn(0, along, across, 0.0, vx=np.full(parts, SPEED))
        return sim
    rc = centre_radius()
    omega = SPEED / rc
    angle = -0.5 * math.pi + along / rc
    radius = rc - across                                # across > 0: left, the inside
    x, y = radius * np.cos(angle), radius * np.sin(angle)
    sim.spawn(0, x, y, angle, vx=-omega * y, vy=omega * x, wz=np.full(parts, omega))
    return sim


def time_scene(curved: bool, parts: int, steps: int) -> float:
    """Return the wall time per step [s] of ``steps`` steps of a fresh simulator."""
    sim = populated(curved, parts)
    start = time.perf_counter()
    sim.step(steps)
    elapsed = time.perf_counter() - start
    if sim.n != parts:
        raise RuntimeError(f'bench curve: {parts - sim.n} parts left the belt')
    return elapsed / steps


def run(parts: int, steps: int, rounds: int) -> Dict:
    """Run the interleaved rounds; return the per-step times [s] and the ratio of medians."""
    time_scene(False, parts, 2)                         # compile outside the timings
    time_scene(True, parts, 2)
    straight: List[float] = []
    curve: List[float] = []
    for _ in range(rounds):
        straight.append(time_scene(False, parts, steps))
        curve.append(time_scene(True, parts, steps))
    s, c = statistics.median(straight), statistics.median(curve)
    return {'parts': parts, 'steps': steps, 'rounds': rounds, 'area_m2': WIDTH * length(),
            'straight_s': straight, 'curve_s': curve, 'straight_median_s': s,
            'curve_median_s': c, 'ratio': c / s}


def main(argv: List[str]) -> int:
    """Run the benchmark; print a summary or (``--json``) one JSON object."""
    parser = argparse.ArgumentParser(prog='conveyor-twin bench curve', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--parts', type=int, default=DEFAULT_PARTS, help='discs per scene')
    parser.add_argument('--steps', type=int, default=DEFAULT_STEPS, help='timed steps a round')
    parser.add_argument('--rounds', type=int, default=DEFAULT_ROUNDS,
                        help='rounds, each timing both scenes')
    args = parser.parse_args(argv)
    for name in ('parts', 'steps', 'rounds'):
        if getattr(args, name) < 1:
            parser.error(f'--{name} = {getattr(args, name)}, expected >= 1')
    result = run(args.parts, args.steps, args.rounds)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f'{result["parts"]} discs on {result["area_m2"]:.3f} m^2, {args.steps} steps x '
          f'{args.rounds} rounds (interleaved), wall time per 1 ms step:')
    print(f'  straight belt  median {1e6 * result["straight_median_s"]:8.1f} us')
    print(f'  90 deg curve   median {1e6 * result["curve_median_s"]:8.1f} us')
    print(f'  curve / straight       {result["ratio"]:8.3f}')
    return 0
