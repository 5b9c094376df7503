"""``conveyor-twin bench clog``: clogging at a bottleneck, the micro simulator against a
pymunk reference on the same scenes, gap by gap.

Two scenes on the default cell's belt (:mod:`conveyor_twin.bench.clog_scenes`): ``deflector``,
the cell's 45° deflector extended until its tip leaves G part diameters to the side wall, parts
released on a jittered lattice; ``funnel``, two symmetric walls at 30° to the running direction
narrowing to an opening of G diameters, parts released at random upstream. N spacers
(d = 10 mm) start at the belt speed, the same positions for both engines per seed. A part has
*passed* once its centre is a radius beyond the bottleneck; a run has *stopped* (clogged) when
no part passed during the last second of the window while parts remain upstream.

Per scene and gap: the clog counts of both engines with their 95 % Wilson intervals, the fraction
passed (mean and range), the deepest overlap between two parts (sampled every 10 ms, % of a
diameter) and a verdict: the twin agrees when its clog probability lies inside the reference's
interval and its mean fraction passed within :data:`PASSED_TOLERANCE` of the reference's.

The reference (:mod:`conveyor_twin.bench.clog_reference`) is pymunk at 100 iterations and
0.25 ms steps, with the same friction law as the twin (constant coefficients, the scenes'
part's static and sliding values both their mean); ``--save-reference FILE`` runs it alone and
keeps its per-run results, ``--reference FILE`` uses them instead of running it again,
``--convergence`` runs it at 0.125 ms steps and at 200 iterations as well.

Measured (150 parts, 5 s, 20 seeds and 60 in the four cases at 2-3 d whose clog probability is
neither 0 nor 1, against a reference at 0.25 ms whose clogging agrees with 0.125 ms): the twin
agrees in all 10 cases; the clog probability falls from 20 of 20 runs at 1.5 d to none at 4 d
in both engines and both scenes (closest: deflector 2.5 d, 50 of 60 clogged against 55 [0.82,
0.96], passed 38 % against 35 %). Over 180 seeds that case does not agree: 147 clogged against
165 [0.87, 0.95] (docs/validation.md). A reference run costs about twenty twin runs.
"""

import argparse
import dataclasses
import json
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Dict, List, Optional, Sequence

import numpy as np

from conveyor_twin.bench import clog_reference as reference
from conveyor_twin.bench.clog_scenes import SCENES, Scene, build_scene, quiet_time, run_twin
from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import CONTACT_TOLERANCE_MAX, MicroModel

DEFAULT_GAPS = (1.5, 2, 2.5, 3, 4)  # clear width of the gap [part diameters]
DEFAULT_SEEDS = 20                  # runs per scene and gap (seeds 1..n)
DEFAULT_PARTS = 150
DEFAULT_WINDOW = 5.0                # s of simulated time per run
PASSED_TOLERANCE = 0.10             # largest difference of the mean fraction passed


def wilson(k: int, n: int, z: float = 1.96) -> tuple:
    """Return the Wilson score interval of ``k`` successes in ``n`` trials (95 % by default)."""
    if n == 0:
        return (0.0, 1.0)
    p = k / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # the bounds at 0 and n successes are exactly 0 and 1 (in floats centre + half may fall
    # short of 1, and a twin that clogs every run would lie outside the interval)
    return (0.0 if k == 0 else max(0.0, centre - half), 1.0 if k == n else min(1.0, centre + half))


def summary(runs: Sequence[Dict]) -> Dict:
    """Return the ensemble figures of one engine at one gap."""
    stopped = sum(r['stopped'] for r in runs)
    n = len(runs)
    frac = np.array([r['fraction_passed'] for r in runs])
    lo, hi = wilson(stopped, n)
    return {'runs': n, 'stopped': stopped, 'clog_probability': stopped / n if n else None,
            'clog_interval': [lo, hi],
            'fraction_passed_mean': float(frac.mean()) if n else None,
            'fraction_passed_min': float(frac.min()) if n else None,
            'fraction_passed_max': float(frac.max()) if n else None,
            'max_overlap_pct': max((r['max_overlap_pct'] for r in runs), default=None),
            'wall_s': float(sum(r['wall_s'] for r in runs))}


def verdict(twin: Dict, ref: Dict, tolerance: float = PASSED_TOLERANCE) -> Dict:
    """Return whether the twin's summary agrees with the reference's.

    Agreement: the twin's clog probability inside the reference's 95 % Wilson interval, and
    its mean fraction passed within ``tolerance`` of the reference's.
    """
    lo, hi = wilson(ref['stopped'], ref['runs'])
    p = twin['clog_probability']
    inside = lo <= p <= hi
    diff = twin['fraction_passed_mean'] - ref['fraction_passed_mean']
    within = abs(diff) <= tolerance + 1e-12
    return {'reference_interval': [lo, hi], 'clog_inside': inside,
            'fraction_passed_difference': diff, 'fraction_within': within,
            'agrees': inside and within}


def _one(task: tuple) -> Dict:
    """Run one seed of one engine (a worker process's job)."""
    engine, name, gap, seed, parts, window, settings = task
    scene = build_scene(name, gap)
    pts = scene.release(parts, seed)
    if engine == 'twin':
        return run_twin(scene, pts, window, seed, micro=settings)
    pymunk = settings
    return reference.run_pymunk(scene, pts, window, iterations=pymunk['iterations'],
                                slop=pymunk['slop_m'], step=pymunk['step_s'])


def _run_tasks(tasks: List[tuple], pool: Optional[ProcessPoolExecutor]) -> List[Dict]:
    if pool is None:
        return [_one(t) for t in tasks]
    return list(pool.map(_one, tasks))


def run(scenes: Sequence[str], gaps: Sequence[float], seeds: int, parts: int, window: float, *,
        twin: bool = True, pymunk: Optional[Dict] = None, ref_mode: Optional[str] = 'run',
        ref_path: Optional[str] = None, jobs: int = 1, on_gap=None,
        twin_micro: Optional[Dict] = None) -> Dict:
    """Run the benchmark; return its report.

    ``ref_mode``: ``'run'`` (run pymunk), ``'load'`` (read the runs from ``ref_path``),
    ``'save'`` (run pymunk, write every run to ``ref_path`` as it comes) or None (no
    reference). ``on_gap(scene, gap key, entry)`` is called after each gap. ``twin_micro``:
    the twin's ``micro`` settings that differ from the scenes' cell (e.g.
    ``{'contact_sweep_budget': 0}``).
    """
    twin_micro = dict(twin_micro or {})
    pymunk = pymunk or reference.settings()
    report: Dict = {'parts': parts, 'seeds': seeds, 'window_s': window,
                    'quiet_s': quiet_time(window), 'pymunk': pymunk if ref_mode else None,
                    'reference': ref_path if ref_mode in ('load', 'save') else ref_mode,
                    'passed_tolerance': PASSED_TOLERANCE, 'twin_micro': twin_micro,
                    'scenes': {}}
    base = load_cell(None)
    report['part_diameter_m'] = 2.0 * base.part_types[0].radius
    data = None
    if ref_mode == 'load':
        data = reference.load(ref_path, parts, window, pymunk)
    elif ref_mode == 'save':
        data = reference.new_file(parts, window, pymunk)
    # check the whole file (and build every scene) before the first run
    plan = [(name, gap, build_scene(name, gap, base)) for name in scenes for gap in gaps]
    stored = {}
    if data is not None and ref_mode == 'load':
        for name, gap, scene in plan:
            stored[(name, gap)] = reference.runs_for(
                data, ref_path, scene, ((s, scene.release(parts, s)) for s in range(1, seeds + 1)))
    pool = ProcessPoolExecutor(max_workers=jobs) if jobs > 1 else None
    try:
        for name, gap, scene in plan:
            entry = _gap_entry(scene, seeds, parts, window, twin, pymunk, ref_mode,
                               stored.get((name, gap)), pool, twin_micro)
            if ref_mode == 'save':
                for seed, run_ in enumerate(entry['reference'], start=1):
                    reference.add(data, scene, seed, scene.release(parts, seed), run_)
                reference.save(data, ref_path)
            report['scenes'].setdefault(name, {})[f'{gap:g}'] = entry
            if on_gap:
                on_gap(name, f'{gap:g}', entry)
    finally:
        if pool is not None:
            pool.shutdown()
    return report


def _gap_entry(scene: Scene, seeds: int, parts: int, window: float, twin: bool, pymunk: Dict,
               ref_mode: Optional[str], stored: Optional[list],
               pool: Optional[ProcessPoolExecutor], twin_micro: Dict) -> Dict:
    entry: Dict = {'gap_m': scene.clear_width, 'pass_line_x_m': scene.pass_line,
                   'twin': [], 'reference': []}
    engines = (['twin'] if twin else []) + (['pymunk'] if ref_mode in ('run', 'save') else [])
    tasks = [(engine, scene.name, scene.gap, seed, parts, window,
              twin_micro if engine == 'twin' else pymunk)
             for engine in engines for seed in range(1, seeds + 1)]
    results = _run_tasks(tasks, pool)
    for task, result in zip(tasks, results):
        entry['twin' if task[0] == 'twin' else 'reference'].append(result)
    if stored is not None:
        entry['reference'] = stored
    entry['summary'] = {}
    for name in ('twin', 'reference'):
        if entry[name]:
            entry['summary'][name] = summary(entry[name])
    if 'twin' in entry['summary'] and 'reference' in entry['summary']:
        entry['verdict'] = verdict(entry['summary']['twin'], entry['summary']['reference'])
    return entry


def _cell_text(s: Optional[Dict]) -> List[str]:
    if s is None:
        return ['-', '-', '-']
    lo, hi = s['clog_interval']
    return [f'{s["stopped"]}/{s["runs"]} [{lo:.2f}, {hi:.2f}]',
            f'{s["fraction_passed_mean"]:.0%} ({s["fraction_passed_min"]:.0%}-'
            f'{s["fraction_passed_max"]:.0%})', f'{s["max_overlap_pct"]:.1f}']


def line(gap: str, entry: Dict) -> str:
    """Return one row of the text table."""
    t = _cell_text(entry['summary'].get('twin'))
    r = _cell_text(entry['summary'].get('reference'))
    v = entry.get('verdict')
    if v is None:
        word = '-'
    else:
        word = 'agrees' if v['agrees'] else 'differs (' + ', '.join(
            w for w, bad in (('clog', not v['clog_inside']), ('passed', not v['fraction_within']))
            if bad) + ')'
    return (f'{gap:>4} d {entry["gap_m"] * 1e3:5.1f} mm | {t[0]:>18} {r[0]:>18} | '
            f'{t[1]:>16} {r[1]:>16} | {t[2]:>5} {r[2]:>5} | {word}')


HEADER = ('   gap   width |  clogged: twin     reference     |   passed: twin  reference      '
          '| overlap % d | verdict')

LITERATURE = ('literature (To, Lai and Pak; Janda et al.; Zuriguel et al.): the probability of '
              'a clog falls steeply as the opening grows, in 2D hoppers from near 1 to near 0 '
              'over a narrow range of openings of a few diameters')


def _parse_gaps(values: Sequence[str]) -> List[float]:
    return [float(g) for v in values for g in v.split(',') if g]


def _print_convergence(k: str, label: str, runs: List[Dict]) -> None:
    s = summary(runs)
    lo, hi = s['clog_interval']
    print(f'{k}: {label}: stopped {s["stopped"]}/{s["runs"]} [{lo:.2f}, {hi:.2f}], passed '
          f'{s["fraction_passed_mean"]:.0%} ({s["fraction_passed_min"]:.0%}-'
          f'{s["fraction_passed_max"]:.0%}), overlap <= {s["max_overlap_pct"]:.1f} % d, '
          f'{s["wall_s"]:.0f} s', flush=True)


def _convergence(args, gaps: List[float], pymunk: Dict) -> Dict:
    scenes = [build_scene(name, gap) for name in _scenes(args) for gap in gaps]
    base_runs = {}
    if args.reference:
        data = reference.load(args.reference, args.parts, args.window, pymunk)
        for scene in scenes:
            base_runs[reference.key(scene.name, scene.gap)] = reference.runs_for(
                data, args.reference, scene,
                ((s, scene.release(args.parts, s)) for s in range(1, args.seeds + 1)))
    pool = ProcessPoolExecutor(max_workers=args.jobs) if args.jobs > 1 else None

    def run_many(scene: Scene, iterations: int, step: float) -> List[Dict]:
        setting = reference.settings(iterations, pymunk['slop_m'], step)
        return _run_tasks([('pymunk', scene.name, scene.gap, seed, args.parts, args.window,
                            setting) for seed in range(1, args.seeds + 1)], pool)
    try:
        return reference.convergence(scenes, args.seeds, args.parts, args.window, base_runs,
                                     on_setting=None if args.json else _print_convergence,
                                     run_many=run_many)
    finally:
        if pool is not None:
            pool.shutdown()


def _scenes(args) -> List[str]:
    return list(SCENES) if args.scene == 'both' else [args.scene]


def parser() -> argparse.ArgumentParser:
    """Return the command line parser."""
    p = argparse.ArgumentParser(prog='conveyor-twin bench clog', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--json', action='store_true', help='print one JSON object')
    p.add_argument('--scene', choices=SCENES + ('both',), default='both')
    p.add_argument('--gaps', nargs='+', default=[','.join(f'{g:g}' for g in DEFAULT_GAPS)],
                   help='gap widths [part diameters], separated by spaces or commas')
    p.add_argument('--seeds', type=int, default=DEFAULT_SEEDS, help='runs per scene and gap')
    p.add_argument('--parts', type=int, default=DEFAULT_PARTS, help='parts per run')
    p.add_argument('--window', type=float, default=DEFAULT_WINDOW,
                   help='simulated time per run [s]')
    p.add_argument('--jobs', type=int, default=1, help='runs in parallel processes')
    p.add_argument('--skip-pymunk', action='store_true', help='run the twin only')
    p.add_argument('--sweep-budget', type=int, metavar='VISITS',
                   help="the twin's micro.contact_sweep_budget (default: the cell's, "
                        f'{MicroModel.contact_sweep_budget})')
    p.add_argument('--sweep-tolerance', type=float, metavar='M/S',
                   help="the twin's micro.contact_tolerance (default: the cell's, "
                        f'{MicroModel.contact_tolerance:g} m/s)')
    p.add_argument('--reference', metavar='FILE',
                   help='take the reference runs from FILE (made by --save-reference)')
    p.add_argument('--save-reference', metavar='FILE',
                   help='run the reference alone and write its runs to FILE')
    p.add_argument('--convergence', action='store_true',
                   help='run the reference at its own settings and at ' + ' and '.join(
                       f'{i} iterations, {t * 1e3:g} ms' for i, t in
                       reference.CONVERGENCE_SETTINGS) + ' (--jobs: seeds in parallel)')
    p.add_argument('--pymunk-iterations', type=int, default=reference.PYMUNK_ITERATIONS)
    p.add_argument('--pymunk-slop', type=float, default=reference.PYMUNK_SLOP, help='[m]')
    p.add_argument('--pymunk-step', type=float, default=reference.PYMUNK_STEP, help='[s]')
    return p


def main(argv: List[str]) -> int:
    """Run the benchmark; print a table per scene or (``--json``) one JSON object."""
    p = parser()
    args = p.parse_args(argv)
    try:
        gaps = _parse_gaps(args.gaps)
    except ValueError:
        p.error(f'--gaps: {" ".join(args.gaps)!r} is not a list of numbers')
    if args.seeds < 1 or args.parts < 1 or args.window <= 0.0 or args.jobs < 1 or not gaps \
            or min(gaps) <= 0:
        p.error('--gaps positive, --seeds, --parts and --jobs at least 1, --window positive')
    if args.reference and args.save_reference:
        p.error('--reference and --save-reference exclude each other')
    if args.sweep_budget is not None and args.sweep_budget < 0:
        p.error('--sweep-budget: at least 0 contact visits')
    tolerance = args.sweep_tolerance
    if tolerance is not None and not 0.0 <= tolerance <= CONTACT_TOLERANCE_MAX:
        p.error(f'--sweep-tolerance: 0..{CONTACT_TOLERANCE_MAX:g} m/s')
    if args.skip_pymunk and (args.reference or args.save_reference or args.convergence):
        p.error('--skip-pymunk excludes --reference, --save-reference and --convergence')
    pymunk = reference.settings(args.pymunk_iterations, args.pymunk_slop, args.pymunk_step)
    t0 = time.perf_counter()
    try:
        if args.convergence:
            out = {'convergence': _convergence(args, gaps, pymunk), 'parts': args.parts,
                   'seeds': args.seeds, 'window_s': args.window,
                   'wall_s': time.perf_counter() - t0}
            if args.json:
                print(json.dumps(out))
            return 0
        mode = ('save' if args.save_reference else 'load' if args.reference
                else None if args.skip_pymunk else 'run')
        if not args.json:
            _print_head(args, pymunk, mode)
        last = [None]

        def on_gap(scene: str, gap: str, entry: Dict) -> None:
            if scene != last[0]:
                print(f'\nscene {scene}\n{HEADER}')
                last[0] = scene
            print(line(gap, entry), flush=True)

        report = run(_scenes(args), gaps, args.seeds, args.parts, args.window,
                     twin=not args.save_reference, pymunk=pymunk, ref_mode=mode,
                     ref_path=args.save_reference or args.reference, jobs=args.jobs,
                     on_gap=None if args.json else on_gap,
                     twin_micro=_twin_micro(args))
    except ValueError as err:
        print(f'conveyor-twin bench clog: {err}', file=sys.stderr)
        return 2
    report['wall_s'] = time.perf_counter() - t0
    report['literature'] = LITERATURE
    if args.json:
        print(json.dumps(report))
        return 0
    print(LITERATURE)
    print(f'wall time {report["wall_s"]:.0f} s (load average {_load()})')
    return 0


def _twin_micro(args) -> Dict:
    """Return the twin's ``micro`` settings that the options change."""
    micro = {}
    if args.sweep_budget is not None:
        micro['contact_sweep_budget'] = args.sweep_budget
    if args.sweep_tolerance is not None:
        micro['contact_tolerance'] = args.sweep_tolerance
    return micro


def _print_head(args, pymunk: Dict, mode: Optional[str]) -> None:
    print(f'{args.parts} parts, {args.seeds} seeds per scene and gap, {args.window:g} s '
          f'window; stopped: no passage in the last {quiet_time(args.window):g} s with parts '
          'upstream (95 % Wilson interval); the twin agrees when its clog probability is inside '
          f'the reference\'s interval and its mean fraction passed within '
          f'{PASSED_TOLERANCE * 100:.0f} points')
    if mode != 'save':
        micro = dataclasses.replace(MicroModel(), **_twin_micro(args))
        print(f'twin: contact sweeps at least {micro.contact_sweeps}, a budget of '
              f'{micro.contact_sweep_budget} contact visits per substep, at most '
              f'{micro.contact_sweeps_max}, to a tolerance of {micro.contact_tolerance:g} m/s',
              flush=True)
    if mode:
        source = {'run': 'run now', 'save': f'run now, saved to {args.save_reference}',
                  'load': f'from {args.reference}'}[mode]
        print(f'reference: pymunk, {pymunk["iterations"]} iterations, slop '
              f'{pymunk["slop_m"]:g} m, step {pymunk["step_s"]:g} s ({source})', flush=True)


def _load() -> str:
    try:
        with open('/proc/loadavg', encoding='ascii') as f:
            return f.read().split()[0]
    except OSError:
        return 'unknown'


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
