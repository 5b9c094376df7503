"""``bench clog``: both scenes' gaps measured from their geometry, the releases, the overlap
measure, the Wilson interval and the verdict, the reference file and its refusals, and a tiny
run of both engines whose figures must be in range (not its wall-clock times)."""

import dataclasses
import json
import math

import numpy as np
import pytest

from conveyor_twin.bench import clog, clog_reference, clog_scenes
from conveyor_twin.bench.micro import pymunk_peer
from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import ObstacleKind
from conveyor_twin.micro import MicroSim


@pytest.mark.parametrize('gap', [1.5, 2, 3.5, 6])
def test_deflector_gap_is_narrowed_to_the_asked_clear_width(gap):
    base = load_cell(None)
    scene = clog_scenes.build_scene('deflector', gap, base)
    cell = scene.cell
    d = 2.0 * base.part_types[0].radius
    assert clog_scenes.clearance(cell) == pytest.approx(gap * d, abs=1e-9)
    assert scene.clear_width == pytest.approx(gap * d, abs=1e-9)
    k = clog_scenes._deflector(cell)
    # the deflector keeps its upstream end and its direction
    (ax, ay), (bx, by) = cell.obstacles[k].points
    (a0x, a0y), (b0x, b0y) = base.obstacles[k].points
    assert (ax, ay) == (a0x, a0y)
    cross = (bx - ax) * (b0y - a0y) - (by - ay) * (b0x - a0x)
    assert cross == pytest.approx(0.0, abs=1e-12)
    assert scene.pass_line == pytest.approx(bx + 0.005 + 0.005)
    assert not (cell.sources or cell.sinks or cell.actuators or cell.light_barriers)


@pytest.mark.parametrize('gap', [1.5, 2, 2.5, 3, 4])
def test_funnel_is_symmetric_and_opens_to_the_asked_clear_width(gap):
    base = load_cell(None)
    scene = clog_scenes.build_scene('funnel', gap, base)
    cell = scene.cell
    d = 2.0 * base.part_types[0].radius
    assert not any(o.kind == ObstacleKind.DEFLECTOR for o in cell.obstacles)
    left, right = (next(o for o in cell.obstacles if o.name == n)
                   for n in clog_scenes.FUNNEL_NAMES)
    (lx0, ly0), (lx1, ly1) = left.points
    (rx0, ry0), (rx1, ry1) = right.points
    assert (lx0, lx1) == (rx0, rx1) and (ly0, ly1) == (-ry0, -ry1)
    # each wall at the funnel angle to +x, from the side wall to the opening
    assert math.degrees(math.atan2(ly0 - ly1, lx1 - lx0)) == pytest.approx(
        clog_scenes.FUNNEL_ANGLE_DEG)
    assert ly0 == pytest.approx(0.255)
    # the clear width, measured by sampling both wall surfaces: narrowest at the opening
    s = np.linspace(0.0, 1.0, 2001)
    pl = np.stack([lx0 + s * (lx1 - lx0), ly0 + s * (ly1 - ly0)], axis=1)
    pr = np.stack([rx0 + s * (rx1 - rx0), ry0 + s * (ry1 - ry0)], axis=1)
    dist = np.hypot(*(pl[:, None, :] - pr[None, :, :]).transpose(2, 0, 1))
    width = dist.min() - 0.5 * (left.thickness + right.thickness)
    assert width == pytest.approx(gap * d, abs=1e-9)
    assert scene.clear_width == pytest.approx(gap * d, abs=1e-9)
    assert clog_scenes.funnel_clearance(cell) == pytest.approx(gap * d, abs=1e-9)
    assert scene.pass_line == pytest.approx(lx1 + 0.5 * left.thickness + d / 2)
    assert lx1 == max(p[0] for p in base.obstacles[clog_scenes._deflector(base)].points)


def test_segments_distance_matches_sampling():
    rng = np.random.default_rng(7)
    s = np.linspace(0.0, 1.0, 401)
    for _ in range(30):
        a, b, c, e = rng.uniform(-1.0, 1.0, (4, 2))
        p = a + s[:, None] * (b - a)
        q = c + s[:, None] * (e - c)
        sampled = np.hypot(*(p[:, None, :] - q[None, :, :]).transpose(2, 0, 1)).min()
        exact = clog_scenes.segments_distance(a, b, c, e)
        assert exact <= sampled + 1e-12
        assert sampled - exact < 0.01


@pytest.mark.parametrize('name', clog_scenes.SCENES)
def test_release_is_upstream_and_free_of_overlaps(name):
    scene = clog_scenes.build_scene(name, 3)
    cell = scene.cell
    r = cell.part_types[0].radius
    pts = scene.release(150, seed=4)
    assert pts.shape == (150, 2)
    assert clog_scenes.deepest_overlap(pts, r) == 0.0
    assert np.abs(pts[:, 1]).max() < 0.25 - r
    bottleneck = [o for o in cell.obstacles
                  if o.kind == ObstacleKind.DEFLECTOR or o.name in clog_scenes.FUNNEL_NAMES]
    assert pts[:, 0].max() < min(p[0] for o in bottleneck for p in o.points) - r
    assert not np.array_equal(pts, scene.release(150, seed=5))
    assert np.array_equal(pts, scene.release(150, seed=4))


def test_deepest_overlap_equals_all_pairs():
    rng = np.random.default_rng(3)
    r = 0.005
    for _ in range(20):
        pts = rng.uniform(0.0, 0.12, (60, 2))
        d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        d[np.diag_indices(60)] = np.inf
        assert clog_scenes.deepest_overlap(pts, r) == pytest.approx(
            max(0.0, 2 * r - d.min()), abs=1e-15)


def test_tiny_run_of_both_engines_reports_figures_in_range(capsys):
    pytest.importorskip('pymunk')
    assert clog.main(['--gaps', '4', '--seeds', '2', '--parts', '30', '--window', '1.5',
                      '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['parts'] == 30 and report['seeds'] == 2 and report['window_s'] == 1.5
    assert report['quiet_s'] == 1.0 and report['pymunk'] == clog_reference.settings()
    assert set(report['scenes']) == set(clog_scenes.SCENES)
    for name in clog_scenes.SCENES:
        entry = report['scenes'][name]['4']
        assert entry['gap_m'] == pytest.approx(0.04)
        for engine in ('twin', 'reference'):
            runs = entry[engine]
            assert len(runs) == 2
            for run in runs:
                assert 0 <= run['passed'] <= 30
                assert run['fraction_passed'] == run['passed'] / 30
                assert 0.0 <= run['max_overlap_pct'] < 100.0
                # a four-diameter opening and a few parts: they flow, nothing clogs
                assert run['passed'] > 0 and not run['stopped']
                assert 0.5 <= run['last_pass_s'] <= 1.5
            s = entry['summary'][engine]
            assert s['runs'] == 2 and s['stopped'] == 0 and s['clog_probability'] == 0.0
            assert 0.0 < s['fraction_passed_min'] <= s['fraction_passed_mean'] <= 1.0
        assert entry['verdict']['clog_inside']
    assert 'To, Lai and Pak' in report['literature']


def _report(capsys, args):
    """Run bench clog with ``args`` (and --json); return its report."""
    assert clog.main(args + ['--json']) == 0
    return json.loads(capsys.readouterr().out)


def _twin_runs(report, scene, gap):
    """Return the twin's runs of one scene and gap in a report, without their wall times."""
    return [{k: v for k, v in run.items() if k != 'wall_s'}
            for run in report['scenes'][scene][gap]['twin']]


def test_parallel_jobs_give_the_same_runs(capsys):
    args = ['--scene', 'funnel', '--gaps', '3', '--seeds', '2', '--parts', '20', '--window',
            '0.5', '--skip-pymunk']
    one = _report(capsys, args)
    two = _report(capsys, args + ['--jobs', '2'])
    assert _twin_runs(one, 'funnel', '3') == _twin_runs(two, 'funnel', '3')
    assert len(_twin_runs(one, 'funnel', '3')) == 2
    assert 'reference' not in one['scenes']['funnel']['3']['summary']


def test_the_sweep_settings_reach_the_twin_and_change_an_arch(capsys):
    """--sweep-budget and --sweep-tolerance set the twin's solver where an arch forms: the
    cell's own values change nothing, others change the runs, and the report names them. (At
    the default tolerance 16 full sweeps already converge this arch; at 1e-5 m/s they do not,
    so the budget shows there.)"""
    args = ['--scene', 'deflector', '--gaps', '2', '--seeds', '1', '--parts', '60', '--window',
            '1.0', '--skip-pymunk']
    default = _report(capsys, args)
    same = _report(capsys, args + ['--sweep-budget', '200000', '--sweep-tolerance', '3e-4'])
    tight = _report(capsys, args + ['--sweep-tolerance', '1e-5'])
    fixed = _report(capsys, args + ['--sweep-budget', '0', '--sweep-tolerance', '1e-5'])
    assert default['twin_micro'] == {}
    assert same['twin_micro'] == {'contact_sweep_budget': 200000, 'contact_tolerance': 3e-4}
    assert fixed['twin_micro'] == {'contact_sweep_budget': 0, 'contact_tolerance': 1e-5}
    runs = _twin_runs(default, 'deflector', '2')
    assert _twin_runs(same, 'deflector', '2') == runs
    assert _twin_runs(tight, 'deflector', '2') != runs
    assert _twin_runs(fixed, 'deflector', '2') != _twin_runs(tight, 'deflector', '2')
    for bad in (['--sweep-budget', '-1'], ['--sweep-tolerance', '-1e-4'],
                ['--sweep-tolerance', '0.5']):
        with pytest.raises(SystemExit):
            clog.main(args + bad)


def test_wilson_interval():
    assert clog.wilson(0, 10)[0] == 0.0 and clog.wilson(10, 10)[1] == 1.0
    for n in range(1, 200):   # exactly, at every n (at 60 the formula gives 1 - 1e-16)
        assert clog.wilson(n, n)[1] == 1.0 and clog.wilson(0, n)[0] == 0.0
    lo, hi = clog.wilson(5, 10)
    assert lo < 0.5 < hi and lo == pytest.approx(1.0 - hi)
    assert clog.wilson(1, 10) == pytest.approx(tuple(1.0 - b for b in clog.wilson(9, 10)[::-1]))
    # textbook values: 0 of 20 -> [0, 0.161], 3 of 5 -> [0.231, 0.882]
    assert clog.wilson(0, 20)[1] == pytest.approx(0.1611, abs=1e-4)
    assert clog.wilson(3, 5) == pytest.approx((0.2307, 0.8824), abs=1e-4)


def _summary(stopped, runs, passed):
    return {'stopped': stopped, 'runs': runs, 'clog_probability': stopped / runs,
            'fraction_passed_mean': passed}


def test_verdict_needs_the_clog_probability_inside_and_the_fraction_within_ten_points():
    ref = _summary(12, 20, 0.30)          # interval [0.387, 0.781]
    lo, hi = clog.wilson(12, 20)
    v = clog.verdict(_summary(10, 20, 0.35), ref)
    assert v['clog_inside'] and v['fraction_within'] and v['agrees']
    assert v['reference_interval'] == [lo, hi]
    assert v['fraction_passed_difference'] == pytest.approx(0.05)
    v = clog.verdict(_summary(5, 20, 0.30), ref)        # 0.25 < 0.387
    assert not v['clog_inside'] and v['fraction_within'] and not v['agrees']
    v = clog.verdict(_summary(12, 20, 0.45), ref)       # 15 points more
    assert v['clog_inside'] and not v['fraction_within'] and not v['agrees']
    assert clog.verdict(_summary(12, 20, 0.40), ref)['fraction_within']   # 10 points: inside
    assert clog.verdict(_summary(0, 20, 1.0), _summary(0, 20, 0.95))['agrees']


def test_a_reference_file_for_other_parameters_is_refused(tmp_path, capsys):
    pytest.importorskip('pymunk')
    path = str(tmp_path / 'reference.json')
    base = ['--scene', 'funnel', '--gaps', '3', '--seeds', '1', '--parts', '5', '--window',
            '0.2']
    assert clog.main(base + ['--save-reference', path, '--json']) == 0
    saved = json.loads(capsys.readouterr().out)
    assert saved['scenes']['funnel']['3']['twin'] == []
    assert clog.main(base + ['--reference', path, '--json']) == 0
    used = json.loads(capsys.readouterr().out)
    assert used['scenes']['funnel']['3']['reference'] == saved['scenes']['funnel']['3'][
        'reference']
    for other, field in ((['--window', '0.3'], 'window_s'), (['--parts', '6'], 'parts'),
                         (['--gaps', '2.5'], 'funnel/2.5'), (['--seeds', '2'], 'seed 2'),
                         (['--scene', 'deflector'], 'deflector/3'),
                         (['--pymunk-iterations', '50'], 'pymunk')):
        assert clog.main(base + other + ['--reference', path]) == 2
        err = capsys.readouterr().err
        assert path in err and field in err, err
    # the scene's geometry changed since the file was made
    with open(path, encoding='utf-8') as f:
        data = json.load(f)
    data['entries']['funnel/3']['parameters']['obstacles'][-1]['friction'] = 0.3
    with open(path, 'w', encoding='utf-8') as f:
        json.dump(data, f)
    scene = clog_scenes.build_scene('funnel', 3)
    loaded = clog_reference.load(path, 5, 0.2, clog_reference.settings())
    with pytest.raises(ValueError, match=r'funnel/3: obstacles\[\d\]\.friction is 0.3'):
        clog_reference.runs_for(loaded, path, scene, [(1, scene.release(5, 1))])
    with pytest.raises(ValueError, match='start positions'):
        data = clog_reference.load(path, 5, 0.2, clog_reference.settings())
        data['entries']['funnel/3']['parameters'] = scene.parameters()
        clog_reference.runs_for(data, path, scene, [(1, scene.release(5, 2))])
    with open(path, 'w', encoding='utf-8') as f:
        f.write('{"format": "something else"}')
    with pytest.raises(ValueError, match='not a bench clog reference'):
        clog_reference.load(path, 5, 0.2, clog_reference.settings())
    # a file of an earlier version of the peer (its belt drive let jams creep) is refused
    older = dict(clog_reference.new_file(5, 0.2, clog_reference.settings()), version=1)
    clog_reference.save(older, path)
    with pytest.raises(ValueError, match=f'version is 1 there but {clog_reference.VERSION}'):
        clog_reference.load(path, 5, 0.2, clog_reference.settings())


def test_a_gap_that_is_not_positive_or_wider_than_the_cells_is_refused():
    for gap in (0.0, -1.0, 15.0):
        with pytest.raises(ValueError):
            clog_scenes.gap_cell(gap)
    for gap in (0.0, -1.0, 50.0):
        with pytest.raises(ValueError, match='funnel gap'):
            clog_scenes.funnel_cell(gap)
    with pytest.raises(ValueError, match='scene'):
        clog_scenes.build_scene('hopper', 2)


def _one_disc_cell(obstacles=()):
    cell = clog_scenes.funnel_cell(4)
    return dataclasses.replace(cell, obstacles=tuple(obstacles), micro=dataclasses.replace(
        cell.micro, capacity=1))


@pytest.mark.parametrize('v0, w0', [(0.0, 0.0), (0.5, 50.0), (0.3, 60.0), (0.5, -3.0)])
def test_the_peers_belt_drive_is_ours_on_one_disc(v0, w0):
    """From rest, spinning down at the belt speed, and sliding and spinning at once (the
    footprint's coupling): the same velocity and spin as ours after 20 ms."""
    pytest.importorskip('pymunk')
    cell = _one_disc_cell()
    space, drive, dt = pymunk_peer(cell, np.array([[1.0, 0.0]]))
    body = next(iter(space.bodies))
    body.velocity = (v0, 0.0)
    body.angular_velocity = w0
    for _ in range(20):
        drive()
        space.step(dt)
    sim = MicroSim(cell, seed=1)
    sim.spawn(0, 1.0, 0.0, 0.0, vx=v0, wz=w0)
    sim.step(20)
    view = sim.parts_view()
    assert body.velocity.x == pytest.approx(float(view.vx[0]), abs=1e-9)
    assert body.velocity.y == pytest.approx(0.0, abs=1e-12)
    assert body.angular_velocity == pytest.approx(float(view.wz[0]), abs=1e-6)
    assert view.vx[0] != v0 or view.wz[0] != w0     # the drive acted


def test_the_peers_belt_drive_does_not_let_a_held_part_creep():
    """A disc that barely rolls (a millionfold inertia), pushed by the belt against a wall at
    60 degrees to the running direction with enough friction to hold it (tan 30 degrees = 0.58
    < 1.0), stays where it is: the drive acts before pymunk's contact solve, so no step moves it
    into the wall first (from where the position correction, along the normal only, would
    leave it further along the wall every step)."""
    pytest.importorskip('pymunk')
    base = load_cell(None)
    wall = next(o for o in base.obstacles if o.kind == ObstacleKind.WALL)
    u = np.array([0.5, math.sqrt(3.0) / 2.0])            # along the wall
    n = np.array([-u[1], u[0]])                          # its normal, upstream
    a, b = np.array([1.0, 0.0]) - 0.15 * u, np.array([1.0, 0.0]) + 0.15 * u
    obstacle = dataclasses.replace(wall, name='held', points=(tuple(a), tuple(b)),
                                   friction=1.0, restitution=0.0)
    cell = _one_disc_cell([obstacle])
    part = dataclasses.replace(cell.part_types[0], inertia=1e6 * cell.part_types[0].inertia)
    cell = dataclasses.replace(cell, part_types=(part,))
    r = part.radius
    start = np.array([1.0, 0.0]) + n * (r + 0.5 * obstacle.thickness)
    space, drive, dt = pymunk_peer(cell, start[None, :], iterations=100, step=5e-4)
    body = next(iter(space.bodies))
    body.velocity = (0.0, 0.0)
    for _ in range(2000):                                # 1 s
        drive()
        space.step(dt)
    moved = np.array(body.position) - start
    assert abs(float(moved @ u)) < 1e-5                  # 0.01 mm along the wall in 1 s
    assert abs(float(moved @ n)) < 2e-4                  # within the slop of the wall


def test_the_scenes_part_has_a_constant_friction_the_peers():
    base = load_cell(None)
    part = base.part_types[0]
    assert part.friction_static > part.friction_sliding      # the spacer's own law falls
    for name in clog_scenes.SCENES:
        scene = clog_scenes.build_scene(name, 2.5, base)
        p = scene.cell.part_types[0]
        mean = 0.5 * (part.friction_static + part.friction_sliding)
        assert p.friction_static == p.friction_sliding == pytest.approx(mean)
        assert scene.parameters()['part']['friction_static'] == pytest.approx(mean)
        assert dataclasses.replace(p, friction_static=part.friction_static,
                                   friction_sliding=part.friction_sliding) == part


def _slide_along_wall(cell, engine):
    """Push a disc that cannot roll (a millionfold inertia) from rest against a wall at 80
    degrees to the running direction for 1 s; return how far it moved along the wall [m]."""
    base = load_cell(None)
    wall = next(o for o in base.obstacles if o.kind == ObstacleKind.WALL)
    angle = math.radians(80.0)
    u = np.array([math.cos(angle), math.sin(angle)])     # along the wall
    n = np.array([-u[1], u[0]])                          # its normal, upstream
    centre = np.array([1.0, 0.0])
    obstacle = dataclasses.replace(wall, name='slope', restitution=0.0, friction=0.15,
                                   points=(tuple(centre - 0.15 * u), tuple(centre + 0.15 * u)))
    cell = dataclasses.replace(cell, obstacles=(obstacle,), micro=dataclasses.replace(
        cell.micro, capacity=1))
    part = dataclasses.replace(cell.part_types[0], inertia=1e6 * cell.part_types[0].inertia)
    cell = dataclasses.replace(cell, part_types=(part,))
    start = centre + n * (part.radius + 0.5 * obstacle.thickness + 1e-4)    # 0.1 mm clear
    if engine == 'pymunk':
        space, drive, dt = pymunk_peer(cell, start[None, :], iterations=100, step=5e-4)
        body = next(iter(space.bodies))
        body.velocity = (0.0, 0.0)
        for _ in range(2000):
            drive()
            space.step(dt)
        end = np.array(body.position)
    else:
        sim = MicroSim(cell, seed=1)
        sim.spawn(0, start[0], start[1], 0.0, vx=0.0)
        sim.step(int(round(1.0 / sim.dt)))
        view = sim.parts_view()
        end = np.array([float(view.x[0]), float(view.y[0])])
    return float((end - start) @ u)


def test_a_disc_slides_along_a_wall_alike_in_both_engines_with_the_scenes_friction():
    """The belt pushes the disc into the wall at 80 degrees: with the wall's constant 0.15 it
    slides at 0.5 m/s (cos 80 - 0.15 sin 80) = 13 mm/s in both engines; with the spacer's own
    law the twin's static 0.21 holds it (tan 80 < 1 / 0.21), which pymunk's constant friction
    could not model."""
    pytest.importorskip('pymunk')
    cell = clog_scenes.build_scene('funnel', 4).cell
    twin = _slide_along_wall(cell, 'twin')
    peer = _slide_along_wall(cell, 'pymunk')
    assert twin > 0.008 and peer > 0.008
    assert twin == pytest.approx(peer, rel=0.02)
    own = dataclasses.replace(cell, part_types=load_cell(None).part_types)
    assert abs(_slide_along_wall(own, 'twin')) < 1e-4


def test_convergence_runs_every_setting_and_takes_stored_runs_for_the_references_own():
    scene = clog_scenes.build_scene('funnel', 3)
    asked = []

    def run_many(s, iterations, step):
        asked.append((s.name, s.gap, iterations, step))
        return [{'setting': (iterations, step), 'seed': seed} for seed in (1, 2)]
    stored = [{'stored': seed} for seed in (1, 2, 3)]
    seen = []
    out = clog_reference.convergence([scene], 2, 5, 0.2, {'funnel/3': stored},
                                     on_setting=lambda k, label, runs: seen.append(label),
                                     run_many=run_many)
    assert asked == [('funnel', 3, i, t) for i, t in clog_reference.CONVERGENCE_SETTINGS]
    own = (f'{clog_reference.PYMUNK_ITERATIONS} iterations, '
           f'{clog_reference.PYMUNK_STEP * 1e3:g} ms')
    assert seen[0] == own and list(out['funnel/3']) == seen
    assert out['funnel/3'][own] == stored[:2]
    assert len(seen) == 1 + len(clog_reference.CONVERGENCE_SETTINGS)
