"""``conveyor-twin bench plant``: a plant of 1, 2, 4 and 8 cells in fast mode, all cells in one
process against one process per cell, side by side.

The plant is a chain: a feeder cell (a 0.4 m belt at 1 m/s fed with 10 mm discs at
:data:`FEED_RATE`) and relays (the same belt without a source), each handing its parts to the
next through a link of :data:`DELAY` s; the last cell's sink is the end of the line. One
process: :class:`~conveyor_twin.plant.runner.PlantRunner` (no ROS, batches in memory).
Processes: ``conveyor-twin plant --processes --no-streams`` (each cell a process, the links
over ROS 2 topics on this machine); its real-time factor is the slowest cell's simulated over
wall time from its first step to its last (waits for its neighbours included). Figures per
size: the real-time factor, the parts that left the line per wall second (simulated
throughput), and cell-steps per wall second; the speed-up of processes over one process; and
where adding cells stops paying (the throughput per cell falls by more than half).
"""

import argparse
import json
import os
from pathlib import Path
import statistics
import subprocess
import sys
import tempfile
import time
from typing import Callable, Dict, List, Optional

DEFAULT_SIZES = (1, 2, 4, 8)
DEFAULT_DURATION = 20.0   # s simulated per run
DEFAULT_ROUNDS = 1
FEED_RATE = 40.0          # parts/s into the first cell
DELAY = 0.1               # s, every link
STEP = 0.001              # s, every cell's step

_CELL = '''cell: {{name: {name}, step: %r, seed: 1}}
belts:
  - {{name: main, start: [0.0, 0.0], end: [0.4, 0.0], width: 0.2, speed: 1.0, max_speed: 2.0,
     acceleration: 5.0, friction: 0.4}}
obstacles:
  - {{name: wall_left, kind: wall, points: [[0.0, 0.105], [0.4, 0.105]]}}
  - {{name: wall_right, kind: wall, points: [[0.0, -0.105], [0.4, -0.105]]}}
part_types:
  - {{name: disc, shape: disc, radius: 0.005, height: 0.01, mass: 0.003}}
{sources}sinks:
  - {{name: exit, region: [0.38, -0.12, 0.5, 0.12]}}
micro: {{capacity: 2000}}
''' % STEP
_SOURCE = '''sources:
  - {{name: feed, part_type: disc, region: [0.02, -0.08, 0.08, 0.08], rate: {rate},
     pattern: poisson, velocity: belt, yaw: random}}
'''


def write_plant(folder: Path, cells: int) -> Path:
    """Write the benchmark's chain of ``cells`` cells into ``folder``; return the plant file."""
    (folder / 'feeder.yaml').write_text(_CELL.format(name='feeder',
                                                     sources=_SOURCE.format(rate=FEED_RATE)))
    (folder / 'relay.yaml').write_text(_CELL.format(name='relay', sources=''))
    lines = ['plant: {name: bench_chain, seed: 1}', 'cells:']
    for k in range(cells):
        lines.append(f'  - {{name: c{k}, file: {"feeder" if k == 0 else "relay"}.yaml, '
                     f'placement: {{x: {0.5 * k}}}}}')
    if cells > 1:
        lines.append('links:')
    for k in range(cells - 1):
        lines.append(f'  - {{name: l{k}, from: {{cell: c{k}, sink: exit}}, to: '
                     f'{{cell: c{k + 1}, belt: main}}, delay: {DELAY}}}')
    path = folder / f'chain_{cells}.yaml'
    path.write_text('\n'.join(lines) + '\n')
    return path


def one_process(path: Path, duration: float) -> Dict[str, float]:
    """Run the plant in this process; return wall time [s], left and cell-steps."""
    from conveyor_twin.plant.loader import load_plant
    from conveyor_twin.plant.runner import PlantRunner
    plant = load_plant(path)
    runner = PlantRunner(plant)
    runner.run_to(10)  # kernels loaded, not timed
    steps = int(round(duration / plant.step))
    t0 = time.perf_counter()
    runner.run_to(steps)
    wall = time.perf_counter() - t0
    ledger = runner.ledger()
    if ledger.residual != 0.0:
        raise RuntimeError(f'plant run lost or duplicated parts:\n{ledger.text()}')
    sim = (steps - 10) * plant.step
    return {'wall_s': wall, 'rtf': sim / wall, 'left': ledger.left,
            'parts_per_s': ledger.left / wall,
            'cell_steps_per_s': len(plant.cells) * (steps - 10) / wall}


def processes(path: Path, duration: float) -> Dict[str, float]:
    """Run the plant with one process per cell; return the slowest cell's rate and more."""
    cmd = [sys.executable, '-m', 'conveyor_twin.cli', 'plant', str(path), '--processes',
           '--no-streams', '--mode', 'fast', '--duration', repr(duration), '--json',
           '--quiet']
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1800)
    if out.returncode != 0:
        raise RuntimeError(f'plant run failed ({out.returncode}): {out.stderr[-2000:]}')
    summary = json.loads(out.stdout)   # the summary is all stdout carries
    rtf = min(summary['cells_rtf'].values())
    wall = duration / rtf
    left = summary['ledger']['left']
    if summary['ledger']['residual'] != 0.0:
        raise RuntimeError(f"plant run lost or duplicated parts: {summary['ledger']}")
    cells = summary['cells']
    return {'wall_s': wall, 'rtf': rtf, 'left': left, 'parts_per_s': left / wall,
            'cell_steps_per_s': cells * duration / STEP / wall,
            'wall_with_start_s': summary['wall_s']}


def run(sizes: List[int], duration: float, rounds: int,
        on_row: Optional[Callable[[int, Dict], None]] = None) -> Dict:
    """Run every size in both layouts ``rounds`` times; return medians per size.

    :param sizes: the numbers of cells of the chains to run.
    :param duration: simulated time of every run [s].
    :param rounds: runs per size and layout (the medians are over these).
    :param on_row: called with each size and its row once it is measured.
    """
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in sizes:
            path = write_plant(Path(tmp), n)
            samples = {'one_process': [], 'processes': []}
            for _ in range(rounds):
                samples['one_process'].append(one_process(path, duration))
                samples['processes'].append(processes(path, duration))
            row = {}
            for layout, runs in samples.items():
                row[layout] = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
            row['speedup'] = row['processes']['rtf'] / row['one_process']['rtf']
            rows[str(n)] = row
            if on_row is not None:
                on_row(n, row)
    return {'duration_s': duration, 'rounds': rounds, 'feed_rate': FEED_RATE,
            'delay_s': DELAY, 'cpus': os.cpu_count(), 'sizes': rows,
            'stops_scaling': stops_scaling(rows)}


def stops_scaling(rows: Dict[str, Dict]) -> Dict[str, int]:
    """Return, per layout, the first size whose cell-steps per second per cell fell below
    half of the single cell's (0: it never did)."""
    out = {}
    for layout in ('one_process', 'processes'):
        base = None
        out[layout] = 0
        for n, row in sorted(rows.items(), key=lambda kv: int(kv[0])):
            per_cell = row[layout]['cell_steps_per_s'] / int(n)
            base = per_cell if base is None else base
            if per_cell < 0.5 * base:
                out[layout] = int(n)
                break
    return out


def _line(n: int, row: Dict) -> str:
    a, b = row['one_process'], row['processes']
    return (f'{n:>5} | {a["rtf"]:8.2f} {a["parts_per_s"]:9.1f} {a["cell_steps_per_s"]:10.0f} | '
            f'{b["rtf"]:8.2f} {b["parts_per_s"]:9.1f} {b["cell_steps_per_s"]:10.0f} | '
            f'{row["speedup"]:6.2f}')


def main(argv: List[str]) -> int:
    """Run the benchmark; print a table or (``--json``) one JSON object."""
    parser = argparse.ArgumentParser(prog='conveyor-twin bench plant', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--sizes', default=','.join(map(str, DEFAULT_SIZES)),
                        help='comma-separated numbers of cells')
    parser.add_argument('--duration', type=float, default=DEFAULT_DURATION,
                        help='simulated time per run [s]')
    parser.add_argument('--rounds', type=int, default=DEFAULT_ROUNDS,
                        help='runs per size and layout (medians)')
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(',') if s]
    if not sizes or min(sizes) < 1 or args.duration <= 0.05 or args.rounds < 1:
        parser.error('--sizes at least 1 cell each, --duration above 0.05 s, --rounds >= 1')
    if not args.json:
        print(f'chain of cells, {args.duration:g} s simulated, fast mode, {FEED_RATE:g} '
              f'parts/s fed, links of {DELAY:g} s; {os.cpu_count()} CPUs; medians of '
              f'{args.rounds} round(s)')
        print('cells |  one process: rtf  parts/s  cell-steps/s |  processes: rtf  parts/s  '
              'cell-steps/s | speed-up', flush=True)
    report = run(sizes, args.duration, args.rounds,
                 on_row=None if args.json else lambda n, r: print(_line(n, r), flush=True))
    if args.json:
        print(json.dumps(report, sort_keys=True))
    else:
        stop = report['stops_scaling']
        for layout, n in stop.items():
            what = (f'stops scaling at {n} cells (cell-steps/s per cell below half of one '
                    'cell\'s)' if n else 'keeps at least half of one cell\'s rate per cell')
            print(f'{layout.replace("_", " ")}: {what}')
    return 0
