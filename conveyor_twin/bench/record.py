"""``conveyor-twin bench record``: CPU cost of recording at 1 kHz, and the largest real-time load.

The stream set of a default-cell-like run, per simulated step (1 ms): ``parts`` with N parts,
``belt_states`` (2 belts), ``actuator_states`` (1), ``light_barriers`` (4), ``/clock``, a
``light_barrier_edges`` message every 50 steps, and a 600 x 50 ``density`` grid recorded every
100th step (``decimation``). The CDR bytes are encoded beforehand (a pool of
:data:`POOL_STEPS` distinct steps of moving parts, cycled), so only recording is measured.

1. Cost: for each compression, one simulated second of messages is fed to
   :class:`~conveyor_twin.record.writer.McapRecorder` at full speed and the writer thread is
   waited for until its queue is empty; the CPU time of the writer thread
   (``pthread_getcpuclockid``) and of the feeding thread (``record()`` calls: decimation,
   queueing) are reported per simulated second, as the median of ``--seconds`` repetitions.
2. Real time: N is raised (x2 from ``--start-parts``, then bisected) while a recording paced at
   1 kHz on absolute deadlines (the twin's pacer) for ``--seconds`` drops nothing and its
   queue drains within :data:`DRAIN_LIMIT` after the last step. The largest N that passes is
   reported per compression.

Writer CPU near one core per simulated second means the writer cannot keep up at 1 kHz (it
shares the GIL with the simulation thread too, so in-process the margin is smaller still).
"""

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin import contract
from conveyor_twin.record.topics import resolve
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.wire import cdr

DT_NS = 1_000_000
POOL_STEPS = 50
DENSITY_DECIMATION = 100
EDGE_EVERY = 50
NX, NY = 600, 50
BELTS = ('infeed', 'main')
ACTUATORS = ('deflector',)
BARRIERS = ('lb_in', 'lb_mid', 'lb_out', 'lb_reject')
DEFAULT_PARTS = 1000
COMPRESSIONS = ('none', 'lz4', 'zstd')
#: Longest drain of the queue after the last paced step for a real-time pass [s].
DRAIN_LIMIT = 0.1

_STREAMS = (contract.PARTS, contract.DENSITY, contract.LIGHT_BARRIERS,
            contract.LIGHT_BARRIER_EDGES, contract.BELT_STATES, contract.ACTUATOR_STATES,
            contract.CLOCK)
#: Recorded names (no namespace) of the streams.
_PARTS, _DENSITY, _BARRIERS, _EDGES, _BELTS, _ACTUATORS, _CLOCK = (resolve(t.name)
                                                                   for t in _STREAMS)
_TYPES = {resolve(t.name): t.type_name for t in _STREAMS}


def message_pool(n_parts: int, seed: int = 0) -> List[List[Tuple[str, bytes]]]:
    """Return :data:`POOL_STEPS` steps of (topic, cdr bytes) with N parts jostling on a belt."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0.0, 5.0, n_parts)
    y = rng.uniform(-0.2, 0.2, n_parts)
    yaw = rng.uniform(-np.pi, np.pi, n_parts)
    vx = 0.5 + rng.normal(0.0, 0.01, n_parts)
    vy = rng.normal(0.0, 0.01, n_parts)
    wz = rng.normal(0.0, 0.1, n_parts)
    ids = np.arange(1, n_parts + 1, dtype=np.uint32)
    types = (ids % 2).astype(np.uint16)
    grid = cdr.DensityGridEncoder('cell', 'buffer', 0.0, -0.25, 0.01, NX, NY)
    gx = np.arange(NX) * 0.01
    pool = []
    for k in range(POOL_STEPS):
        t = k * DT_NS
        # a jam: every field changes every step (constant fields would flatter compression)
        vx = vx + rng.normal(0.0, 1e-3, n_parts)
        vy = vy + rng.normal(0.0, 1e-3, n_parts)
        wz = wz + rng.normal(0.0, 1e-2, n_parts)
        x = x + vx * 1e-3
        y = y + vy * 1e-3
        yaw = yaw + wz * 1e-3
        speeds = np.array([0.5, 0.5])
        density = np.tile((200.0 * np.exp(-(gx - 3.0 - 0.5e-3 * k) ** 2)).astype(np.float32),
                          (NY, 1))
        step = [
            (_CLOCK, cdr.encode_clock(t)),
            (_PARTS, cdr.encode_part_states(t, 'cell', k, ids, types, x, y, yaw, vx, vy, wz)),
            (_BELTS, cdr.encode_belt_states(t, 'cell', BELTS, speeds, speeds)),
            (_ACTUATORS, cdr.encode_actuator_states(t, 'cell', ACTUATORS, [0.1], [0.1])),
            (_BARRIERS, cdr.encode_light_barrier_states(
                t, 'cell', k, BARRIERS, np.array([k % 7 == 0, False, True, False]),
                np.array([k, 0, 1, 0], dtype=np.uint32))),
            (_DENSITY, grid.encode(t, k, density, float(density.sum()) * 1e-4)),
        ]
        if k % EDGE_EVERY == 0:
            step.append((_EDGES,
                         cdr.encode_light_barrier_edge(t, 'cell', 'lb_in', True, 1)))
        pool.append(step)
    return pool


def _recorder(path: str, compression: str, queue_size: int = 20000) -> McapRecorder:
    rec = McapRecorder(path, compression=compression, queue_size=queue_size,
                       decimation={_DENSITY: DENSITY_DECIMATION})
    for topic, type_name in _TYPES.items():
        rec.add_topic(topic, type_name)
    return rec


def _writer_cpu(rec: McapRecorder) -> float:
    """Return the CPU time of the recorder's writer thread [s] (private attribute, bench only)."""
    return time.clock_gettime(time.pthread_getcpuclockid(rec._thread.ident))


def _drain(rec: McapRecorder, limit: float = 60.0) -> float:
    """Wait until the writer's queue is empty; return the wait [s]."""
    start = time.monotonic()
    while rec.queued() and time.monotonic() - start < limit:
        time.sleep(0.0005)
    return time.monotonic() - start


def cost(pool: Sequence[Sequence[Tuple[str, bytes]]], compression: str, directory: str,
         seconds: int) -> Dict[str, float]:
    """Measure CPU per simulated second of the writer and of the feeding thread [s/s].

    :return: medians over ``seconds`` repetitions of one simulated second each, the file size
        per simulated second [MB] and the message count per second.
    """
    path = os.path.join(directory, f'bench_cost_{compression}.mcap')
    writer, feeder, wall = [], [], []
    step = 0
    with _recorder(path, compression, queue_size=10**6) as rec:
        _drain(rec)
        for _ in range(seconds):
            w0, f0, t0 = _writer_cpu(rec), time.thread_time(), time.perf_counter()
            for _ in range(1000):
                t = step * DT_NS
                for topic, data in pool[step % len(pool)]:
                    rec.record(topic, t, data)
                step += 1
            f1 = time.thread_time()
            _drain(rec)
            writer.append(_writer_cpu(rec) - w0)
            feeder.append(f1 - f0)
            wall.append(time.perf_counter() - t0)
        counts = {name: s.recorded for name, s in rec.stats.topics.items()}
    size = os.path.getsize(path)
    os.remove(path)
    return {'writer_cpu_s_per_sim_s': statistics.median(writer),
            'feeder_cpu_s_per_sim_s': statistics.median(feeder),
            'wall_s_per_sim_s': statistics.median(wall),
            'mb_per_sim_s': size / 1e6 / seconds,
            'messages_per_sim_s': sum(counts.values()) / seconds}


def realtime_trial(n_parts: int, compression: str, directory: str,
                   seconds: float) -> Dict[str, float]:
    """Record N parts paced at 1 kHz; return drops, drain time and writer CPU per second."""
    from conveyor_twin.coord.timing import DeadlinePacer

    pool = message_pool(n_parts)
    path = os.path.join(directory, f'bench_rt_{compression}_{n_parts}.mcap')
    steps = int(round(seconds * 1000))
    with _recorder(path, compression) as rec:
        _drain(rec)
        w0 = _writer_cpu(rec)
        pacer = DeadlinePacer(DT_NS)
        for step in range(steps):
            t = step * DT_NS
            for topic, data in pool[step % len(pool)]:
                rec.record(topic, t, data)
            pacer.wait_next()
        drain = _drain(rec)
        cpu = _writer_cpu(rec) - w0
        dropped = rec.stats.dropped
    os.remove(path)
    return {'parts': n_parts, 'dropped': dropped, 'drain_s': drain,
            'writer_cpu_s_per_sim_s': cpu / seconds, 'overruns': pacer.overruns,
            'ok': dropped == 0 and drain <= DRAIN_LIMIT}


def max_parts(compression: str, directory: str, seconds: float, start: int,
              limit: int, bisections: int = 3, log=print) -> Tuple[Optional[int], List[dict]]:
    """Return the largest part count recorded in real time, and every trial."""
    trials = []
    good, bad = None, None
    n = start
    while n <= limit:
        trial = realtime_trial(n, compression, directory, seconds)
        trials.append(trial)
        log(f'  {compression:<5} N={n:>6}: dropped {trial["dropped"]}, drain '
            f'{trial["drain_s"] * 1e3:.1f} ms, writer {trial["writer_cpu_s_per_sim_s"]:.3f} '
            f'CPU s/s -> {"ok" if trial["ok"] else "behind"}')
        if not trial['ok']:
            bad = n
            break
        good = n
        n *= 2
    if good is not None and bad is not None:
        for _ in range(bisections):
            mid = (good + bad) // 2
            if mid in (good, bad):
                break
            trial = realtime_trial(mid, compression, directory, seconds)
            trials.append(trial)
            log(f'  {compression:<5} N={mid:>6}: dropped {trial["dropped"]}, drain '
                f'{trial["drain_s"] * 1e3:.1f} ms -> {"ok" if trial["ok"] else "behind"}')
            good, bad = (mid, bad) if trial['ok'] else (good, mid)
    return good, trials


def main(argv: List[str]) -> int:
    """Run the recording benchmark; print figures (or one JSON object)."""
    p = argparse.ArgumentParser(prog='conveyor-twin bench record', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--parts', type=int, default=DEFAULT_PARTS,
                   help='parts per message for the cost measurement')
    p.add_argument('--compressions', nargs='+', default=list(COMPRESSIONS),
                   choices=COMPRESSIONS)
    p.add_argument('--seconds', type=int, default=3,
                   help='simulated seconds per cost measurement and per real-time trial')
    p.add_argument('--start-parts', type=int, default=500,
                   help='first part count of the real-time search')
    p.add_argument('--max-parts', type=int, default=64000,
                   help='largest part count tried in the real-time search')
    p.add_argument('--no-realtime', action='store_true', help='skip the real-time search')
    p.add_argument('--dir', default=None, help='directory for the scratch files (default: '
                   'a temporary directory)')
    p.add_argument('--json', action='store_true', help='print one JSON object')
    args = p.parse_args(argv)
    log = (lambda *a, **k: print(*a, file=sys.stderr, **k)) if args.json else print
    result: Dict[str, object] = {'parts': args.parts, 'step_ms': 1.0,
                                 'density': f'{NX}x{NY} every {DENSITY_DECIMATION} steps',
                                 'cost': {}, 'max_realtime_parts': {}, 'trials': {}}
    with tempfile.TemporaryDirectory(dir=args.dir) as directory:
        pool = message_pool(args.parts)
        log(f'recording cost per simulated second at 1 kHz, {args.parts} parts '
            f'(median of {args.seconds} s):')
        for compression in args.compressions:
            c = cost(pool, compression, directory, args.seconds)
            result['cost'][compression] = c
            log(f"  {compression:<5} writer {c['writer_cpu_s_per_sim_s']:.3f} CPU s, record() "
                f"{c['feeder_cpu_s_per_sim_s']:.3f} CPU s, wall {c['wall_s_per_sim_s']:.3f} s, "
                f"{c['mb_per_sim_s']:.1f} MB, {c['messages_per_sim_s']:.0f} messages")
        if not args.no_realtime:
            log(f'largest part count recorded in real time ({args.seconds} s paced at 1 kHz, '
                f'no drop, drain <= {DRAIN_LIMIT * 1e3:.0f} ms):')
            for compression in args.compressions:
                best, trials = max_parts(compression, directory, args.seconds,
                                         args.start_parts, args.max_parts, log=log)
                result['max_realtime_parts'][compression] = best
                result['trials'][compression] = trials
                log(f'  {compression:<5} -> {best}')
    if args.json:
        print(json.dumps(result, sort_keys=True))
    return 0
