"""``conveyor-twin bench scale``: step time vs parts on the cell, pure micro and multi-scale.

Scene: a long straight belt (``--length`` m by 1 m, 0.5 m/s, side walls, exit sink) with
light barriers at x = 2, 10 and 20 m; ``N`` spacers (10 mm discs) are laid on a lattice at
4000 parts/m^2 from x = 0.3 m on, moving with the belt. Pure micro: one ``MicroSim`` over the
whole cell (policy ``micro``). Multi-scale: the same cell with one ``auto`` zone (grid 5 cm,
tiles 0.05 m, to macro above 2500 /m^2, to micro below 800 /m^2, sensor windows 0.01 m around
the barriers); all tiles outside sensor windows start macro (the parts there are deposited),
then the policy runs. Each case runs ``--warmup`` steps, then ``--steps`` timed steps of the
whole :class:`~conveyor_twin.coord.twin.Twin` (micro, macro, hand-over, ledger); the table
gives median, p99 and mean per 1 ms step and the parts on the cell at the end.

Figures and the machine they were measured on: docs/benchmarks.md. At 5,000 parts
multi-scale runs at about the speed of pure micro: free flow is cheap at the micro scale, and
the multi-scale step still pays the macro solver over the whole 30 m grid (~0.06 ms) and ~5
hand-overs each way per step. At 100,000 parts the micro step of the ~1,000-1,600 parts at
the sensor windows (~0.25 ms) and ~12 releases and captures per step (each release checked
against all micro parts by ``place``) dominate.
"""

import argparse
import json
import math
import statistics
import time
from typing import Dict, List

import numpy as np

from conveyor_twin.cell.loader import cell_from_mapping
from conveyor_twin.coord.assembly import build_twin

DEFAULT_MICRO = '1000,5000,20000'
DEFAULT_MULTI = '1000,5000,20000,100000'
DEFAULT_STEPS = 500
DEFAULT_WARMUP = 200
DENSITY = 4000.0      # parts/m^2 of the initial lattice
WIDTH = 1.0           # m, belt width
SPEED = 0.5           # m/s
BARRIERS = (2.0, 10.0, 20.0)


def scene(length: float, policy: str, capacity: int):
    """Return the benchmark cell of ``length`` [m] with one zone of ``policy``."""
    w = WIDTH / 2
    zone = {'name': 'belt', 'policy': policy, 'region': [0.0, -w, length, w],
            'resolution': 0.05,
            'auto': {'tile': 0.05, 'to_macro_density': 2500.0, 'to_micro_density': 800.0,
                     'min_dwell': 0.2, 'sensor_margin': 0.01}}
    data = {
        'cell': {'name': 'bench_scale', 'step': 0.001, 'seed': 1},
        'belts': [{'name': 'main', 'start': [0.0, 0.0], 'end': [length, 0.0], 'width': WIDTH,
                   'speed': SPEED, 'max_speed': 2.0, 'acceleration': 2.0, 'friction': 0.35}],
        'obstacles': [
            {'name': 'left', 'kind': 'wall', 'points': [[0.0, w + 0.005], [length, w + 0.005]],
             'thickness': 0.01},
            {'name': 'right', 'kind': 'wall',
             'points': [[0.0, -w - 0.005], [length, -w - 0.005]], 'thickness': 0.01}],
        'part_types': [{'name': 'spacer', 'shape': 'disc', 'radius': 0.005, 'height': 0.01,
                        'mass': 0.0047, 'inertia': 7.3e-8, 'restitution': 0.4,
                        'friction_static': 0.25, 'friction_sliding': 0.18,
                        'friction_transition_speed': 0.01}],
        'sinks': [{'name': 'exit', 'region': [length - 0.1, -w - 0.1, length + 0.3, w + 0.1]}],
        'light_barriers': [{'name': f'lb_{x:g}', 'start': [x, -w], 'end': [x, w],
                            'height': 0.005} for x in BARRIERS if x < length],
        'zones': [zone],
        'micro': {'capacity': capacity},
        'macro': {'variant': 'goettlich', 'scheme': 'upwind'},
    }
    return cell_from_mapping(data, '<bench scale>')


def lattice(n: int) -> np.ndarray:
    """Return ``(n, 2)`` positions [m]: rows across the belt at :data:`DENSITY`, from x = 0.3."""
    s = 1.0 / math.sqrt(DENSITY)
    rows = int((WIDTH - 0.03) / s) + 1
    ys = -0.5 * (rows - 1) * s + np.arange(rows) * s
    k = np.arange(n)
    return np.stack([0.3 + (k // rows) * s, ys[k % rows]], axis=1)


def run_case(n: int, policy: str, steps: int, warmup: int) -> Dict[str, float]:
    """Time ``steps`` steps with ``n`` parts laid out; return the statistics [s]."""
    pos = lattice(n)
    length = max(30.0, float(pos[-1, 0]) + 2.0)
    cell = scene(length, policy, capacity=max(2 * n, 2000) if policy == 'micro' else 30000)
    built = build_twin(cell, seed=1)
    twin, micro, coupling = built.twin, built.micro, built.coupling
    if policy == 'micro':
        micro.sim.spawn(0, pos[:, 0], pos[:, 1], 0.0, SPEED, 0.0)
    else:
        tiles = coupling.regions[0].tiles
        # lay the parts down tile block by tile block so the micro capacity is never exceeded
        block = 20000
        for a in range(0, n, block):
            p = pos[a:a + block]
            micro.sim.spawn(0, p[:, 0], p[:, 1], 0.0, SPEED, 0.0)
            coupling.force_tiles('belt', np.ones_like(tiles.macro))
    twin.step(warmup)
    times = []
    for _ in range(steps):
        t0 = time.perf_counter()
        twin.step(1)
        times.append(time.perf_counter() - t0)
    times.sort()
    led = coupling.ledger() if coupling.enabled else None
    on_cell = (led['micro'] + led['macro'] + led['pending']) if led else float(micro.sim.n)
    return {'policy': policy, 'parts': n, 'on_cell': on_cell,
            'micro_parts': float(micro.sim.n), 'median': statistics.median(times),
            'p99': times[min(len(times) - 1, int(0.99 * len(times)))],
            'mean': statistics.fmean(times),
            'residual': float(led['residual']) if led else 0.0}


def main(argv: List[str]) -> int:
    """Run the scale benchmark; print a table or, with ``--json``, a JSON document."""
    parser = argparse.ArgumentParser(prog='conveyor-twin bench scale',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--json', action='store_true', help='print JSON')
    parser.add_argument('--steps', type=int, default=DEFAULT_STEPS, help='timed steps per case')
    parser.add_argument('--warmup', type=int, default=DEFAULT_WARMUP, help='untimed steps')
    parser.add_argument('--micro', default=DEFAULT_MICRO, help='part counts, pure micro')
    parser.add_argument('--multi', default=DEFAULT_MULTI, help='part counts, multi-scale')
    args = parser.parse_args(argv)
    results = []
    for policy, counts in (('micro', args.micro), ('auto', args.multi)):
        for n in (int(c) for c in counts.split(',') if c):
            results.append(run_case(n, policy, args.steps, args.warmup))
            if not args.json:
                r = results[-1]
                print(f"{r['policy']:>5} N={r['parts']:>6}  on cell {r['on_cell']:9.1f}  "
                      f"micro {int(r['micro_parts']):>6}  median {r['median'] * 1e3:7.3f} ms  "
                      f"p99 {r['p99'] * 1e3:7.3f} ms  mean {r['mean'] * 1e3:7.3f} ms",
                      flush=True)
    speedup = {}
    for n in sorted({r['parts'] for r in results}):
        m = [r for r in results if r['parts'] == n and r['policy'] == 'micro']
        a = [r for r in results if r['parts'] == n and r['policy'] == 'auto']
        if m and a:
            speedup[str(n)] = m[0]['median'] / a[0]['median']
    if args.json:
        print(json.dumps({'unit': 's per 1 ms step', 'results': results,
                          'speedup_median': speedup}, indent=2))
    else:
        for n, s in speedup.items():
            print(f'speed-up multi-scale over pure micro at N={n}: {s:.1f}x (medians)')
    return 0
