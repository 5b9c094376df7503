"""``conveyor-twin bench macro``: time per 1 ms macro step, every variant and scheme.

Scene: a belt at 0.5 m/s carrying 10 mm spacers (rho_max 11547 /m^2) across the grid, a
45 degree deflector across 70 % of the width at mid-length, fed at the inlet with
0.3 rho_max; the grid is pre-run until a queue has formed in front of the deflector (so the
cap and the collision operator are really at work), then each step is timed. Baselines in
the same run: a plain NumPy split upwind step
(:func:`conveyor_twin.macro.reference.upwind_step`, no cap, no bookkeeping) and PyClaw's 2D
advection (classic solver, dimensional splitting, first order) when clawpack is installed.

Rows ``*_free``: the same belt without the deflector (free flow, nothing reaches rho_max):
plain capped advection, and the Göttlich variant with its operator idle.

Figures and the machine they were measured on: docs/benchmarks.md. Where the time goes in the
capped upwind jam step on 400 x 100 (thread CPU, isolated kernels): x sweep demand and update
~35 us, the x pre-check ~20 us, cuts ~8 us, y sweep ~10 us, the Python wrapper ~9-15 us; the
operator adds ~30-140 us as the jam grows (100-2600 full cells). The y sweep works only on faces
with a y velocity and the operator's faces, the x cut only on faces whose cut condition holds,
the collision operator only within r + 1 cells of full cells.

Ratios NumPy / numba in the same run (``conveyor-twin bench macro``, 400 x 100, medians of
three runs, load 2-3): free capped upwind 4.7x, capped upwind in the jam 3.9x, Göttlich upwind
in the jam 1.9x (NumPy's step has no cap, no operator and no bookkeeping).

The PyClaw peer needs clawpack, whose Fortran kernels are built at install time: install a
Fortran compiler, then clawpack into the environment (Debian/Ubuntu:
``sudo apt-get install gfortran`` and ``.venv/bin/pip install clawpack``); without it the
PyClaw row is reported as skipped. The benchmark installs nothing itself.
"""

import argparse
import dataclasses
import json
import math
import statistics
import time
from typing import Dict, List, Optional

import numpy as np

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Belt, Obstacle, Zone
from conveyor_twin.macro import MacroSim
from conveyor_twin.macro.reference import upwind_step

DEFAULT_GRIDS = '400x100,2000x500'
DEFAULT_STEPS = 2000
SPEED = 0.5           # m/s
LENGTH = 4.0          # m, belt and grid length
INFLOW = 0.3          # of rho_max


def _cell(nx: int, ny: int, deflector: bool = True):
    """Return the bench cell: a 4 m belt on an ``nx x ny`` grid, with or without deflector."""
    base = load_cell(None)
    h = LENGTH / nx
    width = ny * h
    belt = Belt('main', (0.0, 0.0), (LENGTH, 0.0), width, SPEED, 2.0, 2.0, 0.35)
    x0 = 0.5 * LENGTH
    deflector_obstacle = Obstacle(
        'deflector', 'deflector', ((x0, 0.5 * width), (x0 + 0.7 * width, -0.2 * width)),
        thickness=max(0.01, h))
    zone = Zone('bench', 'macro', (0.0, -0.5 * width, LENGTH, 0.5 * width), h)
    obstacles = (deflector_obstacle,) if deflector else ()
    return dataclasses.replace(base, belts=(belt,), obstacles=obstacles, actuators=(),
                               zones=(zone,))


def _prepare(cell, variant: str, scheme: str) -> MacroSim:
    sim = MacroSim(cell, variant=variant, scheme=scheme)
    rates = np.zeros(sim.grid.n_boundary)
    rates[:sim.ny] = INFLOW * sim.rho_max * SPEED * sim.resolution
    sim.set_inflow(rates)
    # Pre-run until the material has reached the deflector and queues.
    warm = int(math.ceil(0.6 * LENGTH / SPEED / sim.dt))
    sim.step(warm)
    return sim


def _time_steps(fn, steps: int) -> List[float]:
    """Return the wall-clock durations [s] of ``steps`` calls of ``fn``."""
    out = []
    for _ in range(steps):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


def _cpu_steps(fn, steps: int) -> List[float]:
    """Return the thread CPU durations [s] of ``steps`` calls (less sensitive to load)."""
    out = []
    for _ in range(steps):
        t0 = time.thread_time()
        fn()
        out.append(time.thread_time() - t0)
    return out


def _pyclaw_step_time(sim: MacroSim, steps: int) -> Optional[float]:
    """Median seconds per 1 ms step of PyClaw's 2D advection on the same grid, or None.

    Classic (wave-propagation) solver, dimensional splitting, first order, fixed dt, outflow
    (extrapolation) boundaries, advancing with ``evolve_to_time`` one fixed step (the twin's) at a time.
    """
    try:
        from clawpack import pyclaw, riemann
    except ImportError:
        return None
    solver = pyclaw.ClawSolver2D(riemann.advection_2D)
    solver.dimensional_split = True
    solver.order = 1
    solver.bc_lower[0] = solver.bc_upper[0] = pyclaw.BC.extrap
    solver.bc_lower[1] = solver.bc_upper[1] = pyclaw.BC.extrap
    solver.dt_initial = sim.dt
    solver.dt_variable = False
    g = sim.grid
    x = pyclaw.Dimension(g.origin_x, g.origin_x + g.nx * g.h, g.nx, name='x')
    y = pyclaw.Dimension(g.origin_y, g.origin_y + g.ny * g.h, g.ny, name='y')
    domain = pyclaw.Domain([x, y])
    state = pyclaw.State(domain, 1)
    state.problem_data['u'] = SPEED
    state.problem_data['v'] = 0.0
    state.q[0, :, :] = sim.density.T
    solution = pyclaw.Solution(state, domain)
    solver.setup(solution)
    solver.dt = sim.dt  # dt_initial alone leaves PyClaw's default step (0.1 s) in place

    def one() -> None:
        # no end time: exactly one step of the fixed dt (an end time that a sum of float dt
        # misses by round-off makes PyClaw refuse: "dt does not divide (tend-tstart)")
        solver.evolve_to_time(solution)

    return statistics.median(_time_steps(one, steps))


def run(grids: List[str], steps: int) -> Dict[str, dict]:
    """Return ``{grid: {name: median seconds per 1 ms step, ...}}``."""
    results: Dict[str, dict] = {}
    for spec in grids:
        nx, ny = (int(v) for v in spec.lower().split('x'))
        cell = _cell(nx, ny)
        n = steps if nx * ny <= 100_000 else max(50, steps // 20)
        row: Dict[str, object] = {'nx': nx, 'ny': ny, 'steps': n}
        sim = None
        for variant in ('capped', 'goettlich'):
            for scheme in ('upwind', 'limited'):
                sim = _prepare(cell, variant, scheme)
                sim.step(5)
                row[f'{variant}_{scheme}'] = statistics.median(_time_steps(sim.step, n))
                row[f'{variant}_{scheme}_cpu'] = statistics.median(_cpu_steps(sim.step, n))
                row[f'{variant}_{scheme}_substeps'] = sim.substeps
                row[f'{variant}_{scheme}_full_cells'] = int(
                    np.count_nonzero(sim.density >= sim.rho_max * (1.0 - 1e-9)))
        # Free flow (no obstacle, nothing reaches rho_max): plain capped advection.
        free = _cell(nx, ny, deflector=False)
        for variant in ('capped', 'goettlich'):
            fsim = _prepare(free, variant, 'upwind')
            row[f'{variant}_upwind_free'] = statistics.median(_time_steps(fsim.step, n))
            row[f'{variant}_upwind_free_cpu'] = statistics.median(_cpu_steps(fsim.step, n))
        assert sim is not None
        rho = sim.density.copy()
        ux, uy = (u.copy() for u in sim.face_velocity)
        k = sim.dt / sim.resolution
        row['numpy_upwind'] = statistics.median(
            _time_steps(lambda: upwind_step(rho, ux, uy, k), max(20, n // 4)))
        row['numpy_upwind_cpu'] = statistics.median(
            _cpu_steps(lambda: upwind_step(rho, ux, uy, k), max(20, n // 4)))
        try:
            row['pyclaw'] = _pyclaw_step_time(sim, max(20, n // 10))
        except Exception as exc:  # noqa: BLE001 - a broken optional baseline is reported
            row['pyclaw'] = None
            row['pyclaw_error'] = f'{type(exc).__name__}: {exc}'
        if row['pyclaw'] is None and 'pyclaw_error' not in row:
            row['pyclaw_error'] = ('clawpack is not installed (apt-get install gfortran, then '
                                  'pip install clawpack)')
        results[spec] = row
    return results


def main(argv: List[str]) -> int:
    """Run the macro benchmark; print a table or, with ``--json``, a JSON document."""
    parser = argparse.ArgumentParser(prog='conveyor-twin bench macro',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--json', action='store_true', help='print JSON')
    parser.add_argument('--steps', type=int, default=DEFAULT_STEPS,
                        help='timed steps per case on grids up to 1e5 cells (1/20 above)')
    parser.add_argument('--grids', default=DEFAULT_GRIDS, help='comma-separated NXxNY list')
    args = parser.parse_args(argv)
    results = run([g for g in args.grids.split(',') if g], args.steps)
    if args.json:
        print(json.dumps({'unit': 's per 1 ms step (median)', 'results': results}, indent=2))
        return 0
    for spec, row in results.items():
        base = row['numpy_upwind']
        print(f'grid {spec} ({row["steps"]} timed steps)')
        for name in ('capped_upwind', 'capped_limited', 'goettlich_upwind', 'goettlich_limited',
                     'capped_upwind_free', 'goettlich_upwind_free', 'numpy_upwind', 'pyclaw'):
            value = row.get(name)
            if value is None:
                print(f'  {name:18s}  skipped: {row.get("pyclaw_error", "")}')
                continue
            ratio = base / value
            cpu = row.get(name + '_cpu')
            cpu_text = f'  (cpu {cpu * 1e3:.3f} ms)' if cpu is not None else ''
            print(f'  {name:18s}  {value * 1e3:8.3f} ms   numpy/this {ratio:6.2f}{cpu_text}')
    return 0
