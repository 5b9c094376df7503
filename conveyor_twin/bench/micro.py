"""``conveyor-twin bench micro``: the micro simulator against pymunk on the same jammed scene.

The scene (``conveyor_twin/cell/bench_micro.yaml``, the peer measurement of architecture.md):
a 2.0 m x 0.5 m belt at 0.5 m/s with side walls and a 45 degree deflector across its whole
width; N discs of 10 mm diameter and 0.01 kg are placed on a hexagonal lattice upstream and
run into the deflector for the warm-up, so the timed steps are a jam. Both engines step at
dt = 1 ms with the same per-pair friction and restitution, the same disc and wall geometry
(walls and deflector as segments of radius 5 mm) and the same belt drive (ours: footprint
friction coupling sliding and spinning, given to pymunk as each disc's force and torque, which
it adds before its contact solve as ours does; :func:`pymunk_peer`). pymunk runs
with its defaults (10 iterations, bounding-box tree) except ``collision_slop = 1e-4 m`` (ours);
its belt drive is applied each step with ``pymunk.batch`` and numpy (no per-body Python).
``pymunk step`` times ``space.step`` alone; ``pymunk total`` adds the drive. The ratios are
pymunk / ours; ``x step`` (against ``space.step`` alone) is the conservative one.

The second part reproduces Hoher et al.'s claim (impulses stable at 1e-3 s, a force-based response
needing ~1e-6 s, ~1000x) on the same scene, one step per step (no automatic substeps), by two
criteria: *stable* in the jam (N discs, 0.3 s: deepest penetration below 10 % of the radius,
no part faster than twice the belt, none through a wall) and *accurate* on one impact (two
scene discs head on at the belt speed: restitution within :data:`IMPACT_TOLERANCE` = 10 % of
its step -> 0 value; the impulse model's is exact at any step). The penalty model runs at two
stiffnesses: the one picked by activity (Rideout and Stein, springs <= 1 % of the least active
element), and the stainless steel the paper's parts are made of (:func:`seed_stiffness`: line
contact of two 10 mm high parts, k = (pi / 4) E* L = 8.3e8 N/m), both with the damping ratio
of the cell's penalty contact (0.11). Basis and assumptions: the paper's text names the
material and says the forces come from Young's moduli and intersection depths, but its parts'
mass and diameter are lost in the extraction, so the scene's 10 g discs stand in; a lighter
part (a hollow spacer) needs a smaller step (dt ~ sqrt(m)). At the steel stiffness the penalty
model is *stable* up to 2e-6 s (500x) and *accurate* to 10 % only up to 1e-6 s (1000x, the
paper's figure; the impact errors per step are printed: 20 % at 2e-6 s, 5 % at 1e-6 s, so a
5 % tolerance would give 5e-7 s); Horváth et al.'s rule dt <= 1/(12 f) for a vibrating element
gives 1.3e-6 s. So the paper's ~1e-6 s follows from steel stiffness plus resolving the contact
oscillation (~12 steps per period), not from stability alone. At the activity-picked
k = 1e5 N/m both criteria give 2e-4 s (5x): the activity-sized spring, far softer than steel,
is what makes penalty contacts affordable.

Measured on the shared 2-core machine (numba 0.68, pymunk 7.3.1, 2000 warm-up + 2000 timed
steps, load average ~2-4; wall clock; pymunk's ``space.step`` alone):

=====  ============================  =====================  ===========================
N      ours median / mean [ms]       pymunk step mean       pymunk / ours
=====  ============================  =====================  ===========================
1000   0.168 / 0.189 (p99 0.29)      2.37                   12.5x (CPU 8.7x)
5000   0.971 / 1.31 (p99 5.5)        20.0                   15.2x (CPU 18.6x)
=====  ============================  =====================  ===========================

The jam is at rest, every part touching its neighbours (2.5 contacts per part at N = 1000, 2.9 at
N = 5000). Deepest overlap in the jam at the end: 0.10 mm (N=1000), 0.14 mm (N=5000), slop
0.1 mm (at most 0.23 mm in the timed jam; 0.8 mm at 0.5 s while the jam forms).
Largest step, N = 100, 0.3 s: impulse 5e-4 s (1e-3 s overlaps 0.52 mm, 2e-3 s 1.8 mm; impact
exact);
penalty at k = 1e5 N/m picked by activity (springs/least active physical element = 0.0046):
stable 2e-4 s, accurate 2e-4 s (impact error 8.9 %; 5e-4 s: 500 %), 5x; penalty at the
stainless-steel k = 8.3e8 N/m: stable 2e-6 s (5e-6 s blows up), accurate 1e-6 s (impact
errors 20 % at 2e-6 s, 5.2 % at 1e-6 s), 1000x; Horváth et al.'s 1/(12 f): 1.3e-6 s.
"""

import argparse
import dataclasses
import json
import math
from pathlib import Path
import sys
import time
from typing import Dict, List, Optional

import numpy as np

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import Cell
from conveyor_twin.micro import MicroSim

SCENE = Path(__file__).resolve().parent.parent / 'cell' / 'bench_micro.yaml'
# Hoher et al.'s parts: "small hollow and cylindrical spacers, made of stainless steel" (their mass
# and diameter are lost in the extracted text); its force-based response takes the forces from
# "the material features, like Young's moduli, and the intersection depths". Two such parts
# standing side by side touch along a line as long as they are high; see seed_stiffness().
STEEL_E = 193e9               # Pa, Young's modulus of stainless steel (AISI 304)
STEEL_NU = 0.29               # Poisson's ratio of stainless steel
# Binary-impact accuracy: the restitution of a head-on impact of two scene discs may differ by
# this fraction from its step -> 0 value (the impulse model's is exact at any step).
IMPACT_TOLERANCE = 0.10
# Horváth et al.: a vibrating element needs dt <= 1 / (12 f), about 12 steps per period.
STEPS_PER_PERIOD = 12
DEFAULT_SIZES = (100, 1000, 5000)
DEFAULT_STEPS = 2000
DEFAULT_WARMUP = 2000
LATTICE_GAP = 0.0002          # m between neighbouring discs when placed


def scene(n: int, *, contact: str = 'impulse', step: Optional[float] = None,
          **micro) -> Cell:
    """Return the benchmark cell with room for ``n`` discs."""
    cell = load_cell(str(SCENE))
    settings = cell.settings if step is None else dataclasses.replace(cell.settings,
                                                                      step=step)
    return dataclasses.replace(cell, settings=settings, micro=dataclasses.replace(
        cell.micro, capacity=max(n, 1), contact=contact, **micro))


def lattice(cell: Cell, n: int) -> np.ndarray:
    """Return (n, 2) disc centres on a hexagonal lattice upstream of the deflector [m]."""
    r = cell.part_types[0].radius
    d = 2.0 * r + LATTICE_GAP
    (x0, y0), (x1, y1) = cell.obstacles[2].points
    half = 0.5 * cell.obstacles[2].thickness
    y_max = cell.belts[0].width / 2 - r - 1e-4
    pts: List[tuple] = []
    row = 0
    while len(pts) < n:
        # rows from the deflector's far end upstream
        x = x1 - (r + half) * math.sqrt(2.0) - 1e-3 - row * d * math.sqrt(3.0) / 2.0
        if x < r:
            raise ValueError(f'{n} discs do not fit upstream of the deflector')
        y = -y_max + (0.5 * d if row % 2 else 0.0)
        while y <= y_max and len(pts) < n:
            # stay on the upstream side of the deflector line x + y = x0 + y0
            if x + y < x0 + y0 - (r + half) * math.sqrt(2.0) - 1e-3:
                pts.append((x, y))
            y += d
        row += 1
    return np.array(pts)


def _stats(samples_ns: np.ndarray) -> Dict[str, float]:
    ms = samples_ns / 1e6
    return {'mean_ms': float(ms.mean()), 'median_ms': float(np.median(ms)),
            'p99_ms': float(np.percentile(ms, 99))}


def jammed_sim(n: int, warmup: int, **kwargs) -> MicroSim:
    """Return a MicroSim of the scene with ``n`` discs after ``warmup`` steps."""
    cell = scene(n, **kwargs)
    sim = MicroSim(cell, seed=cell.settings.seed)
    pts = lattice(cell, n)
    belt = cell.belts[0].speed
    sim.spawn(0, pts[:, 0], pts[:, 1], 0.0, vx=belt)
    sim.step(warmup)
    return sim


def time_ours(n: int, steps: int, warmup: int) -> Dict[str, float]:
    """Time ``steps`` single steps of our simulator on the jam."""
    sim = jammed_sim(n, warmup)
    samples = np.zeros(steps, dtype=np.int64)
    cpu = np.zeros(steps, dtype=np.int64)
    clock = time.perf_counter_ns
    cpu_clock = time.thread_time_ns
    for k in range(steps):
        c0 = cpu_clock()
        t0 = clock()
        sim.step(1)
        samples[k] = clock() - t0
        cpu[k] = cpu_clock() - c0
    result = _stats(samples)
    result.update({f'cpu_{k}': v for k, v in _stats(cpu).items()})
    t0 = clock()
    sim.step(steps)
    result['batched_ms'] = (clock() - t0) / 1e6 / steps
    result['max_penetration_mm'] = max_penetration(sim) * 1e3
    return result


def max_penetration(sim: MicroSim) -> float:
    """Return the deepest disc-disc or disc-wall overlap of the scene's state [m]."""
    view = sim.parts_view()
    r = sim.cell.part_types[0].radius
    pts = np.stack([view.x, view.y], axis=1)
    deepest = 0.0
    if len(view) > 1:
        order = np.argsort(pts[:, 0])
        p = pts[order]
        for shift in range(1, 40):
            d = np.hypot(*(p[shift:] - p[:-shift]).T)
            deepest = max(deepest, float((2 * r - d).max(initial=0.0)))
    for obstacle in sim.cell.obstacles:
        (ax, ay), (bx, by) = obstacle.points
        e = np.array([bx - ax, by - ay])
        f = np.clip(((pts - (ax, ay)) @ e) / (e @ e), 0.0, 1.0)
        d = np.hypot(*(pts - (np.array([ax, ay]) + f[:, None] * e)).T)
        deepest = max(deepest, float((r + obstacle.thickness / 2 - d).max(initial=0.0)))
    return deepest


def pymunk_space(n: int):
    """Return (space, belt drive function, step) of the scene in pymunk with ``n`` discs."""
    cell = scene(n)
    return pymunk_peer(cell, lattice(cell, n))


def pymunk_peer(cell: Cell, positions: np.ndarray, *, iterations: Optional[int] = None,
                slop: Optional[float] = None, step: Optional[float] = None):
    """Return (space, belt drive function, step) of ``cell`` in pymunk.

    Discs of the cell's first part type stand at ``positions`` ((n, 2) [m]) moving at the belt
    speed; every obstacle is a static segment as thick as it is; the coefficients are matched
    per pair (pymunk's are constant: a part pair takes the mean of the part's static and
    sliding coefficients, a part and an obstacle the obstacle's; for a part whose two
    coefficients are equal, as in ``bench clog``, that is the twin's law exactly). One belt
    runs along +x under every disc; the drive is ours
    (:func:`conveyor_twin.micro.drive.belt_drive`): Coulomb friction over the footprint, the
    slip falling by at most ``mu g dt f`` and the spin by the matching torque ``t``, with the
    footprint's coupling of sliding and spinning.

    The drive function must be called before every ``space.step``: it sets each disc's force
    and torque for the coming step, which pymunk adds to the velocities after moving the
    bodies and before its contact solve, as ours drives before its contacts. (Setting the
    velocities instead would move every body by the drive's ``dv dt`` before any contact saw
    it; pymunk's position correction acts along the normals only, so jammed discs would creep
    along their contacts at up to ``mu g dt`` per step, 1.7 mm/s at 0.5 ms, and arches that
    friction holds would fold within a second or two.)

    ``iterations``: pymunk's solver iterations (default: pymunk's 10); ``slop``: its
    ``collision_slop`` (default: the cell's penetration slop); ``step``: the step [s] the drive
    is sized for (default: the cell's).
    """
    import pymunk
    import pymunk.batch

    from conveyor_twin.micro.footprint import (FT_FORCE, FT_TORQUE, RADIUS_PER_SPIN_ARM,
                                               footprint_table)
    from conveyor_twin.micro.state import spin_arm

    part = cell.part_types[0]
    belt = cell.belts[0]
    dt = cell.settings.step if step is None else step
    space = pymunk.Space()
    if iterations is not None:
        space.iterations = int(iterations)
    space.collision_slop = cell.micro.penetration_slop if slop is None else slop
    # pymunk multiplies the two shapes' coefficients: discs carry sqrt(pair value), at least
    # 1e-9 (a pair value of 0 then gives 1e-18, and the obstacles' values stay exact)
    mu_pp = 0.5 * (part.friction_static + part.friction_sliding)
    disc_mu = max(math.sqrt(mu_pp), 1e-9)
    disc_e = max(math.sqrt(part.restitution), 1e-9)
    for obstacle in cell.obstacles:
        a, b = obstacle.points
        seg = pymunk.Segment(space.static_body, a, b, obstacle.thickness / 2)
        seg.friction = obstacle.friction / disc_mu
        seg.elasticity = obstacle.restitution / disc_e
        space.add(seg)
    for x, y in positions:
        body = pymunk.Body(part.mass, part.inertia)
        body.position = (x, y)
        body.velocity = (belt.speed, 0.0)
        shape = pymunk.Circle(body, part.radius)
        shape.friction = disc_mu
        shape.elasticity = disc_e
        space.add(body, shape)
    fields = pymunk.batch.BodyFields.VELOCITY | pymunk.batch.BodyFields.ANGULAR_VELOCITY
    forces = pymunk.batch.BodyFields.FORCE | pymunk.batch.BodyFields.TORQUE
    get_buf = pymunk.batch.Buffer()
    set_buf = pymunk.batch.Buffer()
    ft = footprint_table()
    last = ft.shape[0] - 1
    arm = RADIUS_PER_SPIN_ARM * spin_arm(part)                  # footprint radius [m]
    dv_max = belt.friction * cell.settings.gravity * dt         # slip change, f = 1 [m/s]
    dw_max = dv_max * part.mass * arm / part.inertia            # spin change, t = 1 [rad/s]
    # velocity changes to forces and torques over the step
    scale = np.array([part.mass / dt, part.mass / dt, part.inertia / dt])
    rows = {}

    def layout(count: int):
        # the space's static body is iterated too (once it has shapes or after the first
        # step): find its row when the number of rows changes, and keep it at rest
        if rows.get('count') != count:
            ids_buf = pymunk.batch.Buffer()
            pymunk.batch.get_space_bodies(space, pymunk.batch.BodyFields.BODY_ID, ids_buf)
            ids = np.frombuffer(ids_buf.int_buf(), dtype=np.uintp)
            rows.update(count=count, dynamic=ids != space.static_body.id,
                        out=np.zeros(3 * ids.size))
        return rows['dynamic'], rows['out']

    def drive() -> None:
        get_buf.clear()
        pymunk.batch.get_space_bodies(space, fields, get_buf)
        v = np.frombuffer(get_buf.float_buf(), dtype=np.float64).reshape(-1, 3)
        dynamic, out = layout(v.shape[0])
        dvx = belt.speed - v[:, 0]
        dvy = -v[:, 1]
        d = np.hypot(dvx, dvy)
        # the footprint's factors at q = a |w| / (|slip| + a |w|) (0 without spin: sliding)
        spin = arm * np.abs(v[:, 2])
        q = spin / np.maximum(d + spin, 1e-300) * last
        i = np.minimum(q.astype(np.intp), last - 1)
        u = q - i
        cf = ft[i, FT_FORCE] + u * (ft[i + 1, FT_FORCE] - ft[i, FT_FORCE])
        ct = ft[i, FT_TORQUE] + u * (ft[i + 1, FT_TORQUE] - ft[i, FT_TORQUE])
        f = np.minimum(1.0, dv_max * cf / np.maximum(d, 1e-300))
        w_max = dw_max * ct
        res = out.reshape(-1, 3)
        res[:, 0] = dvx * f
        res[:, 1] = dvy * f
        res[:, 2] = -np.clip(v[:, 2], -w_max, w_max)
        res *= scale
        res[~dynamic] = 0.0
        set_buf.set_float_buf(out)
        pymunk.batch.set_space_bodies(space, forces, set_buf)

    return space, drive, dt


def time_pymunk(n: int, steps: int, warmup: int) -> Dict[str, float]:
    """Time pymunk on the same jam: drive + ``space.step``, and ``space.step`` alone."""
    space, drive, dt = pymunk_space(n)
    for _ in range(warmup):
        drive()
        space.step(dt)
    total = np.zeros(steps, dtype=np.int64)
    step_only = np.zeros(steps, dtype=np.int64)
    cpu = np.zeros(steps, dtype=np.int64)
    clock = time.perf_counter_ns
    cpu_clock = time.thread_time_ns
    for k in range(steps):
        t0 = clock()
        drive()
        t1 = clock()
        c1 = cpu_clock()
        space.step(dt)
        cpu[k] = cpu_clock() - c1
        t2 = clock()
        total[k] = t2 - t0
        step_only[k] = t2 - t1
    result = {f'total_{k}': v for k, v in _stats(total).items()}
    result.update({f'step_{k}': v for k, v in _stats(step_only).items()})
    result.update({f'step_cpu_{k}': v for k, v in _stats(cpu).items()})
    return result


def stable(n: int, contact: str, step: float, duration: float, **micro) -> Dict[str, float]:
    """Run the scene at ``step`` [s] without substeps; return whether it stayed accurate."""
    cell = scene(n, contact=contact, step=step, **micro)
    sim = MicroSim(cell, seed=1, auto_substeps=False, track_activity=False)
    pts = lattice(cell, n)
    sim.spawn(0, pts[:, 0], pts[:, 1], 0.0, vx=cell.belts[0].speed)
    r = cell.part_types[0].radius
    steps = int(round(duration / step))
    chunk = max(1, steps // 20)
    deepest = 0.0
    fastest = 0.0
    escaped = False
    done = 0
    while done < steps:
        k = min(chunk, steps - done)
        sim.step(k)
        done += k
        view = sim.parts_view()
        if not np.all(np.isfinite(view.x)):
            escaped = True
            break
        deepest = max(deepest, max_penetration(sim))
        fastest = max(fastest, float(np.hypot(view.vx, view.vy).max()))
        escaped |= bool(np.any(np.abs(view.y) > 0.25)) or bool(
            np.any(view.x + view.y > 1.5 + r))
    ok = (not escaped and deepest <= 0.1 * r and fastest <= 2.0 * cell.belts[0].speed)
    return {'step': step, 'ok': ok, 'max_penetration_mm': deepest * 1e3,
            'max_speed': fastest, 'escaped': escaped}


def seed_stiffness(cell: Cell) -> float:
    """Return the contact stiffness of two stainless-steel parts of the scene [N/m].

    Two parallel cylinders of height ``L`` pressed together touch along a line; Hertz's line
    contact is nearly linear, its usual linearisation ``k = (pi / 4) E* L`` with the contact
    modulus of two equal materials ``E* = E / (2 (1 - nu^2))`` (stainless steel: E = 193 GPa,
    nu = 0.29, E* = 105 GPa). With the scene's 10 mm high discs: ``k = 8.3e8 N/m``. The part-part
    contact is the stiffest one of the scene (against the aluminium deflector E* is lower and
    the wall does not move: a part on a wall has twice the effective mass of a pair).
    """
    e_star = STEEL_E / (2.0 * (1.0 - STEEL_NU ** 2))
    return 0.25 * math.pi * e_star * cell.part_types[0].height


def contact_frequency(cell: Cell, stiffness: float) -> float:
    """Return the undamped frequency of a part-part contact spring [Hz] (effective mass m/2)."""
    return math.sqrt(stiffness / (0.5 * cell.part_types[0].mass)) / (2.0 * math.pi)


def impact_restitution(contact: str, step: float, **micro) -> float:
    """Return the restitution of a head-on impact of two scene discs at ``step`` [s].

    Belt at rest and frictionless, the discs 10 um apart closing at the belt speed, one step
    per step (no substeps); the run lasts until two contact periods after the touch.
    """
    cell = scene(2, contact=contact, step=step, **micro)
    u = cell.belts[0].speed     # closing speed [m/s]
    belt = dataclasses.replace(cell.belts[0], speed=0.0, friction=0.0)
    cell = dataclasses.replace(cell, belts=(belt,))
    sim = MicroSim(cell, seed=1, auto_substeps=False, track_activity=False)
    r = cell.part_types[0].radius
    gap = 1e-5
    sim.spawn(0, [0.5, 0.5 + 2.0 * r + gap], 0.0, 0.0, vx=[0.5 * u, -0.5 * u])
    k = cell.micro.penalty_stiffness
    period = 1.0 / contact_frequency(cell, k)
    sim.step(int(math.ceil((gap / u + 2.0 * period) / step)) + 1)
    v = sim.parts_view()
    return float((v.vx[1] - v.vx[0]) / u)


def largest_accurate_step(stiffness: float, damping: float) -> Dict:
    """Return the largest :data:`STEP_LADDER` step whose impact restitution is accurate.

    Accurate: within :data:`IMPACT_TOLERANCE` of the converged value (a run at omega dt =
    0.005). Also returns the converged value and every step's error.
    """
    cell = scene(2)
    omega = 2.0 * math.pi * contact_frequency(cell, stiffness)
    micro = {'penalty_stiffness': stiffness, 'penalty_damping': damping}
    converged = impact_restitution('penalty', 0.005 / omega, **micro)
    errors = {}
    largest = None
    for step in STEP_LADDER:
        if omega * step > 4.0:
            continue   # beyond the stability limit (omega dt < 2): the impact explodes
        e = impact_restitution('penalty', step, **micro)
        err = abs(e - converged) / converged
        errors[f'{step:g}'] = err
        if err <= IMPACT_TOLERANCE and largest is None:
            largest = step
            break
    return {'largest_step': largest, 'converged_restitution': converged, 'errors': errors}


STEP_LADDER = (1e-2, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 5e-6, 2e-6, 1e-6,
               5e-7)


def largest_stable_step(n: int, contact: str, duration: float, **micro) -> Dict:
    """Return the largest step of :data:`STEP_LADDER` that passes :func:`stable`, and the runs."""
    runs = []
    for step in STEP_LADDER:
        result = stable(n, contact, step, duration, **micro)
        runs.append(result)
        if result['ok']:
            return {'largest_step': step, 'runs': runs}
    return {'largest_step': None, 'runs': runs}


def main(argv: List[str]) -> int:
    """Run the benchmark; print a table or (``--json``) one JSON object."""
    parser = argparse.ArgumentParser(prog='conveyor-twin bench micro', description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    parser.add_argument('--sizes', default=','.join(map(str, DEFAULT_SIZES)),
                        help='comma-separated disc counts')
    parser.add_argument('--steps', type=int, default=DEFAULT_STEPS, help='timed steps')
    parser.add_argument('--warmup', type=int, default=DEFAULT_WARMUP, help='warm-up steps')
    parser.add_argument('--skip-pymunk', action='store_true', help='time ours only')
    parser.add_argument('--skip-stability', action='store_true',
                        help='skip the penalty/impulse largest-step comparison')
    parser.add_argument('--stability-n', type=int, default=100,
                        help='discs in the largest-step comparison')
    parser.add_argument('--stability-time', type=float, default=0.3,
                        help='simulated time of each largest-step run [s]')
    args = parser.parse_args(argv)
    sizes = [int(s) for s in args.sizes.split(',') if s]
    report: Dict = {'scene': str(SCENE.name), 'dt': 1e-3, 'steps': args.steps,
                    'warmup': args.warmup, 'sizes': {}}
    jammed_sim(10, 2)   # compile outside the timings
    for n in sizes:
        entry = {'ours': time_ours(n, args.steps, args.warmup)}
        if not args.skip_pymunk:
            entry['pymunk'] = time_pymunk(n, args.steps, args.warmup)
            ours = entry['ours']['mean_ms']
            entry['ratio_step'] = entry['pymunk']['step_mean_ms'] / ours
            entry['ratio_total'] = entry['pymunk']['total_mean_ms'] / ours
            entry['ratio_step_cpu_median'] = (entry['pymunk']['step_cpu_median_ms']
                                              / entry['ours']['cpu_median_ms'])
        report['sizes'][str(n)] = entry
        if not args.json:
            _print_size(n, entry)
    if not args.skip_stability:
        from conveyor_twin.micro.activity import pick_contact_stiffness
        base = scene(args.stability_n)
        pick = pick_contact_stiffness(base, seed=1, duration=0.1, settle=0.3,
                                      positions=lattice(base, args.stability_n))
        report['penalty_stiffness'] = pick.stiffness
        report['penalty_activity_ratio'] = pick.ratio
        report['impulse'] = largest_stable_step(args.stability_n, 'impulse',
                                                args.stability_time)
        report['penalty'] = largest_stable_step(
            args.stability_n, 'penalty', args.stability_time,
            penalty_stiffness=pick.stiffness, penalty_damping=pick.damping)
        # the paper's material (stainless steel) stiffness, same damping ratio as the picked pair
        k_seed = seed_stiffness(base)
        seed_damping = pick.damping * math.sqrt(k_seed / pick.stiffness)
        report['penalty_seed_stiffness'] = k_seed
        report['penalty_seed'] = largest_stable_step(
            args.stability_n, 'penalty', args.stability_time,
            penalty_stiffness=k_seed, penalty_damping=seed_damping)
        # accuracy of one impact (the impulse model's restitution is exact at any step)
        report['impulse_impact_restitution'] = impact_restitution('impulse', 1e-3)
        report['penalty_impact'] = largest_accurate_step(pick.stiffness, pick.damping)
        report['penalty_seed_impact'] = largest_accurate_step(k_seed, seed_damping)
        report['penalty_seed_rule_step'] = 1.0 / (STEPS_PER_PERIOD
                                                  * contact_frequency(base, k_seed))
        for key in ('penalty', 'penalty_seed'):
            steps = [report[key]['largest_step'], report[key + '_impact']['largest_step']]
            report[key + '_both'] = None if None in steps else min(steps)
        if not args.json:
            _print_stability(args.stability_n, pick, report)
    if args.json:
        print(json.dumps(report))
    return 0


def _print_stability(n: int, pick, report: Dict) -> None:
    imp = report['impulse']['largest_step']
    print(f'largest step, N = {n} jam (stable: overlap <= 10 % r, speed <= 2 belt, none '
          f'escaped) and one impact (accurate: restitution within {IMPACT_TOLERANCE:.0%} of '
          f'its converged value): impulse {imp} s (impact exact, e = '
          f"{report['impulse_impact_restitution']:.3f})")
    for key, name, k in (('penalty', 'picked by activity', report['penalty_stiffness']),
                         ('penalty_seed', 'stainless steel line contact',
                          report['penalty_seed_stiffness'])):
        both = report[key + '_both']
        errors = ', '.join(f'{step}: {err:.1%}'
                           for step, err in report[key + '_impact']['errors'].items())
        ratio = f'{imp / both:.0f}x' if imp and both else '-'
        print(f'  penalty k = {k:.3g} N/m ({name}): stable {report[key]["largest_step"]} s, '
              f'accurate {report[key + "_impact"]["largest_step"]} s (impact errors {errors}); '
              f'both {both} s, impulse/penalty {ratio}')
    print(f"  Horváth et al.'s rule dt <= 1/(12 f) at the steel stiffness: "
          f"{report['penalty_seed_rule_step']:.2g} s; activity ratio of the picked k "
          f'{pick.ratio:.3g}')


def _print_size(n: int, entry: Dict) -> None:
    o = entry['ours']
    line = (f"N = {n:5d}  ours {o['mean_ms']:.3f} ms mean, {o['median_ms']:.3f} median, "
            f"{o['p99_ms']:.3f} p99, {o['cpu_median_ms']:.3f} CPU median "
            f"({o['batched_ms']:.3f} batched, max overlap {o['max_penetration_mm']:.3f} mm)")
    if 'pymunk' in entry:
        p = entry['pymunk']
        line += (f" | pymunk step {p['step_mean_ms']:.3f} mean, {p['step_p99_ms']:.3f} p99; "
                 f"total {p['total_mean_ms']:.3f} | ratio x{entry['ratio_step']:.2f} step, "
                 f"x{entry['ratio_total']:.2f} total, x{entry['ratio_step_cpu_median']:.2f} "
                 'CPU median step')
    print(line, flush=True)


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
