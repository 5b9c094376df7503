"""The reference of ``bench clog``: pymunk (Chipmunk2D) run close to convergence on the same
scenes, and its cache file.

The peer is built by :func:`conveyor_twin.bench.micro.pymunk_peer` (the peer of ``bench micro``:
the same geometry, per-pair friction and restitution, the same belt drive), run with
:data:`PYMUNK_ITERATIONS` solver iterations, ``collision_slop`` :data:`PYMUNK_SLOP` m and a step
of :data:`PYMUNK_STEP` s (the coarsest step whose clogging agrees with half of it;
``--convergence`` repeats that check). A reference run costs about twenty times a twin run, so
its per-run results can be saved (:func:`save`) and read back (:func:`load`); a file made for other
scene parameters, part counts, windows, pymunk settings or start positions is refused with an
error naming the field.
"""

import json
import os
import time
from typing import Callable, Dict, Iterable, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.bench.clog_scenes import Scene, Watch, positions_digest, samples

PYMUNK_ITERATIONS = 100
PYMUNK_SLOP = 1e-4                  # m
PYMUNK_STEP = 2.5e-4                # s (at 0.5 ms the arches are weaker: see docs/validation.md)
# convergence check: (iterations, step [s]) against the reference's own settings
CONVERGENCE_SETTINGS = ((100, 1.25e-4), (200, 2.5e-4))
FORMAT = 'conveyor_twin bench clog reference'
# 2: the peer's belt drive acts as forces before pymunk's contact solve, with the footprint's
# coupling of sliding and spinning (files of version 1 hold runs whose jams crept)
VERSION = 2


def settings(iterations: int = PYMUNK_ITERATIONS, slop: float = PYMUNK_SLOP,
             step: float = PYMUNK_STEP) -> Dict:
    """Return the pymunk settings as a report / file entry."""
    return {'iterations': int(iterations), 'slop_m': float(slop), 'step_s': float(step)}


def run_pymunk(scene: Scene, positions: np.ndarray, window: float, *,
               iterations: int = PYMUNK_ITERATIONS, slop: float = PYMUNK_SLOP,
               step: float = PYMUNK_STEP) -> Dict:
    """Run the pymunk reference on ``scene`` for ``window`` s; return the run's figures."""
    import pymunk.batch

    from conveyor_twin.bench.micro import pymunk_peer

    t0 = time.perf_counter()
    space, drive, dt = pymunk_peer(scene.cell, positions, iterations=iterations, slop=slop,
                                   step=step)
    ids_buf = pymunk.batch.Buffer()
    pymunk.batch.get_space_bodies(space, pymunk.batch.BodyFields.BODY_ID, ids_buf)
    ids = np.frombuffer(ids_buf.int_buf(), dtype=np.uintp)
    dynamic = ids != space.static_body.id
    buf = pymunk.batch.Buffer()
    watch = Watch(len(positions), scene.pass_line, scene.cell.part_types[0].radius)
    for k, t in samples(window, dt):
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


def key(scene: str, gap: float) -> str:
    """Return the file's key of one scene at one gap."""
    return f'{scene}/{gap:g}'


def new_file(parts: int, window: float, pymunk: Dict) -> Dict:
    """Return an empty reference file's content."""
    return {'format': FORMAT, 'version': VERSION, 'parts': int(parts), 'window_s': float(window),
            'pymunk': dict(pymunk), 'entries': {}}


def add(data: Dict, scene: Scene, seed: int, positions: np.ndarray, run: Dict) -> None:
    """Add one reference run (seed ``seed`` of ``scene``) to a reference file's content."""
    entry = data['entries'].setdefault(key(scene.name, scene.gap),
                                       {'parameters': scene.parameters(), 'runs': {}})
    entry['runs'][str(seed)] = dict(run, release_digest=positions_digest(positions))


def save(data: Dict, path: str) -> None:
    """Write a reference file (whole, then renamed: a reader never sees half of it)."""
    tmp = f'{path}.partial'
    with open(tmp, 'w', encoding='utf-8') as f:
        json.dump(data, f, indent=1)
    os.replace(tmp, path)


def _refuse(path: str, field: str, stored, wanted) -> ValueError:
    return ValueError(f'reference file {path}: {field} is {stored!r} there but {wanted!r} in '
                      'this run; make a new one with --save-reference')


def _same(a, b) -> bool:
    """Compare two JSON values (floats after a JSON round trip)."""
    return json.loads(json.dumps(a)) == json.loads(json.dumps(b))


def _differs(path: str, prefix: str, stored: Dict, wanted: Dict) -> Optional[ValueError]:
    for name in sorted(set(stored) | set(wanted)):
        if not _same(stored.get(name), wanted.get(name)):
            a, b = stored.get(name), wanted.get(name)
            if isinstance(a, dict) and isinstance(b, dict):
                return _differs(path, f'{prefix}{name}.', a, b)
            if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
                for i, (x, y) in enumerate(zip(a, b)):
                    if isinstance(x, dict) and isinstance(y, dict) and not _same(x, y):
                        return _differs(path, f'{prefix}{name}[{i}].', x, y)
            return _refuse(path, prefix + name, a, b)
    return None


def load(path: str, parts: int, window: float, pymunk: Dict) -> Dict:
    """Read a reference file made for ``parts`` parts, a ``window`` [s] and ``pymunk`` settings.

    Raises ValueError naming the file and the field that differs.
    """
    try:
        with open(path, encoding='utf-8') as f:
            data = json.load(f)
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f'reference file {path}: cannot be read ({err})') from err
    if not isinstance(data, dict) or data.get('format') != FORMAT:
        raise ValueError(f'reference file {path}: not a bench clog reference (format '
                         f'{data.get("format") if isinstance(data, dict) else None!r})')
    if data.get('version') != VERSION:
        raise _refuse(path, 'version', data.get('version'), VERSION)
    for field, wanted in (('parts', parts), ('window_s', window), ('pymunk', pymunk)):
        if not _same(data.get(field), wanted):
            raise _refuse(path, field, data.get(field), wanted)
    return data


def runs_for(data: Dict, path: str, scene: Scene,
             starts: Iterable[Tuple[int, np.ndarray]]) -> list:
    """Return the stored runs of ``scene`` for the (seed, start positions) in ``starts``.

    Raises ValueError if the file lacks the scene, gap or a seed, or was made for other scene
    parameters or start positions.
    """
    entry = data['entries'].get(key(scene.name, scene.gap))
    if entry is None:
        raise ValueError(f'reference file {path}: has no runs of {key(scene.name, scene.gap)} '
                         f'(scene {scene.name!r}, gap {scene.gap:g} d; it has '
                         f'{", ".join(sorted(data["entries"])) or "none"})')
    err = _differs(path, f'{key(scene.name, scene.gap)}: ', entry['parameters'],
                   scene.parameters())
    if err:
        raise err
    out = []
    for seed, positions in starts:
        run = entry['runs'].get(str(seed))
        if run is None:
            raise ValueError(f'reference file {path}: {key(scene.name, scene.gap)} has no run '
                             f'of seed {seed} (it has {len(entry["runs"])} seeds)')
        if run.get('release_digest') != positions_digest(positions):
            raise _refuse(path, f'{key(scene.name, scene.gap)} seed {seed}: start positions',
                          run.get('release_digest'), positions_digest(positions))
        out.append({k: v for k, v in run.items() if k != 'release_digest'})
    return out


def convergence(scenes: Sequence[Scene], seeds: int, parts: int, window: float,
                base_runs: Optional[Dict[str, list]] = None, on_setting=None,
                run_many: Optional[Callable[[Scene, int, float], list]] = None) -> Dict:
    """Run the reference at the settings of :data:`CONVERGENCE_SETTINGS` and at its own.

    ``base_runs`` maps a scene key to stored runs at the reference's own settings (seeds
    1..``seeds``), which are then not run again. ``on_setting(key, label, runs)`` is called
    after each setting. ``run_many(scene, iterations, step)`` returns the runs of seeds
    1..``seeds`` (default: one after the other in this process). Returns {scene key: {setting
    label: runs}}.
    """
    out: Dict = {}
    own = (PYMUNK_ITERATIONS, PYMUNK_STEP)
    for scene in scenes:
        k = key(scene.name, scene.gap)
        out[k] = {}
        starts = [scene.release(parts, seed) for seed in range(1, seeds + 1)]
        for iterations, step in (own,) + tuple(CONVERGENCE_SETTINGS):
            label = f'{iterations} iterations, {step * 1e3:g} ms'
            if (iterations, step) == own and base_runs and k in base_runs:
                runs = base_runs[k][:seeds]
            elif run_many is not None:
                runs = run_many(scene, iterations, step)
            else:
                runs = [run_pymunk(scene, pts, window, iterations=iterations, step=step)
                        for pts in starts]
            out[k][label] = runs
            if on_setting:
                on_setting(k, label, runs)
    return out
