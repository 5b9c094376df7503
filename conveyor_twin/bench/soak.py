"""``conveyor-twin bench soak``: the twin for a long realtime run, recording, with a controller.

The twin (``conveyor-twin run``, realtime, the default cell with its feeder) records every
stream in-process (``--record``) while a controller (``examples/stop_on_barrier.py``, its own
process) stops and restarts the belt on every part the infeed light barrier sees. Both processes
keep their traffic on loopback (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) in a ROS domain
claimed for the run. Every ``--sample-period`` seconds the benchmark samples the twin's and the
controller's resident memory (``VmRSS``), the size of the recording, and the twin's progress
line (steps, overruns). At the end it reports:

- growth per hour of the twin's RSS and of the recording (least-squares slope over the samples
  after ``--warmup``) [MiB/h];
- the twin's overruns per hour, and those of the host's floor: the paced C loop of
  ``bench host`` (the twin's pacing without its work) run for ``--floor-window`` seconds before
  and after the twin, scaled to an hour (omitted with ``--floor-window 0``);
- that nothing was lost: the recording closes intact, every per-step stream holds every step
  from the first to the last with no gap or repeat, ``/clock`` holds every step the twin did,
  every topic's sequence numbers are consecutive (a gap is a message the recorder dropped), and
  the recorder's own drop counters are zero.

The figures depend on what else the machine runs: the load average and the CPU share the
hypervisor gave to other guests (``steal``) are printed beside them.
"""

import argparse
import fcntl
import json
import os
import pathlib
import re
import signal
import subprocess
import sys
import tempfile
import time
from typing import Dict, IO, List, Optional, Tuple

import numpy as np

from conveyor_twin import contract
from conveyor_twin.bench.cpu import cpu_times, steal_percent
from conveyor_twin.record.topics import resolve

DEFAULT_DURATION = 3600.0   # s of wall time
DEFAULT_SAMPLE_PERIOD = 10.0  # s between samples
DEFAULT_WARMUP = 60.0       # s of samples left out of the growth fits
DEFAULT_FLOOR_WINDOW = 30.0  # s of the paced floor loop before and after the run
#: The controller's pause [s]: short enough that the belt keeps up with the feeder's 20 parts/s
#: (with the example's 0.5 s every part stops the belt for a second and parts pile up without
#: bound, so neither memory nor step time could reach a steady state).
DEFAULT_PAUSE = 0.02
STEP_NS = 1_000_000
#: Streams published once per step, checked step by step.
PER_STEP = tuple(resolve(t.name) for t in (contract.CLOCK, contract.PARTS, contract.BELT_STATES,
                                          contract.LIGHT_BARRIERS, contract.ACTUATOR_STATES))
# Domain ids clear of the ephemeral port range (ROS 2 "The ROS_DOMAIN_ID"), 0 left out; the
# lock files are those of the test suite's domain claims, so both never share a domain.
DOMAIN_IDS = tuple(range(1, 102)) + tuple(range(215, 233))
DOMAIN_LOCK_PREFIX = 'conveyor_twin_ros_domain_'
_PROGRESS = re.compile(r'step\s+(\d+)\s+parts micro\s+(\d+).*overruns (\d+)')
MIB = 1024.0 * 1024.0


def claim_domain_id() -> Tuple[int, IO[str]]:
    """Claim a ROS domain id for this run (an advisory lock held while the file is open).

    :return: the id and the open lock file (keep it open for the run).
    :raises RuntimeError: when every id is held by another process.
    """
    start = os.getpid() % len(DOMAIN_IDS)
    for k in range(len(DOMAIN_IDS)):
        candidate = DOMAIN_IDS[(start + k) % len(DOMAIN_IDS)]
        lock = open(os.path.join(tempfile.gettempdir(),
                                 f'{DOMAIN_LOCK_PREFIX}{candidate}.lock'), 'w')
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return candidate, lock
    raise RuntimeError('every ROS domain id is held by another process')


def rss_bytes(pid: int) -> Optional[int]:
    """Return the resident memory of a process (``VmRSS``) [bytes], None once it has ended."""
    try:
        with open(f'/proc/{pid}/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def growth_per_hour(t_s: np.ndarray, values: np.ndarray) -> Optional[float]:
    """Return the least-squares slope of ``values`` over ``t_s`` scaled to an hour
    [unit of values per hour], None with fewer than 3 samples."""
    if len(t_s) < 3:
        return None
    slope = np.polyfit(np.asarray(t_s, float), np.asarray(values, float), 1)[0]
    return float(slope * 3600.0)


def default_controller() -> str:
    """Return the path of ``examples/stop_on_barrier.py`` beside the package."""
    return str(pathlib.Path(__file__).resolve().parents[2] / 'examples' / 'stop_on_barrier.py')


def check_recording(path: str, steps: Optional[int]) -> Dict[str, object]:
    """Scan a closed recording and say what, if anything, was lost.

    :param path: the MCAP file of the run.
    :param steps: steps the twin reported done (None if unknown).
    :return: per-topic message counts and first/last step, and ``lost`` findings (empty: nothing
        lost).
    """
    from conveyor_twin.record import reader, scan
    findings: List[str] = []
    if not reader.is_complete(path):
        findings.append('the recording has no valid footer')
    report = scan.ScanReport(path, 0)
    prev_step: Dict[int, int] = {}
    first_step: Dict[int, int] = {}
    prev_seq: Dict[int, int] = {}
    counts: Dict[int, int] = {}
    step_gaps: Dict[int, int] = {}
    seq_gaps: Dict[int, int] = {}
    per_step_ids: Dict[int, bool] = {}
    for m in scan.iter_scan(path, report):
        cid = m.channel_id
        per_step = per_step_ids.get(cid)
        if per_step is None:
            channel = report.channels.get(cid)
            per_step = per_step_ids[cid] = channel is not None and channel.topic in PER_STEP
        counts[cid] = counts.get(cid, 0) + 1
        seq = prev_seq.get(cid)
        if seq is not None and m.sequence != seq + 1:
            seq_gaps[cid] = seq_gaps.get(cid, 0) + 1
        prev_seq[cid] = m.sequence
        if per_step:
            step = m.log_time // STEP_NS
            last = prev_step.get(cid)
            if last is None:
                first_step[cid] = step
            elif step != last + 1:
                step_gaps[cid] = step_gaps.get(cid, 0) + 1
            prev_step[cid] = step
    if report.damaged:
        findings.append(f'damaged chunks at offsets {[offset for offset, _ in report.damaged]}')
    topics: Dict[str, Dict[str, object]] = {}
    for cid, channel in report.channels.items():
        entry: Dict[str, object] = {'messages': counts.get(cid, 0)}
        if per_step_ids.get(cid):
            entry.update(first_step=first_step.get(cid), last_step=prev_step.get(cid),
                         step_gaps=step_gaps.get(cid, 0))
            if step_gaps.get(cid):
                findings.append(f'{channel.topic}: {step_gaps[cid]} gaps in its steps')
        if seq_gaps.get(cid):
            entry['sequence_gaps'] = seq_gaps[cid]
            findings.append(f'{channel.topic}: {seq_gaps[cid]} gaps in its sequence numbers')
        topics[channel.topic] = entry
    for name in PER_STEP:
        if not topics.get(name, {}).get('messages'):
            findings.append(f'{name}: no message recorded')
    clock = topics.get(contract.CLOCK.name, {})
    if steps is not None and clock.get('messages'):
        if clock.get('first_step') != 1 or clock.get('last_step') != steps:
            findings.append(f"/clock covers steps {clock.get('first_step')}-"
                            f"{clock.get('last_step')}, the twin did 1-{steps}")
    return {'topics': topics, 'lost': findings}


def floor_window(seconds: float) -> Optional[Dict[str, object]]:
    """Run the host's paced floor loop for ``seconds``; None where it cannot run."""
    if seconds <= 0:
        return None
    try:
        from conveyor_twin.bench.host import paced_floor
    except ImportError:
        return None
    try:
        return paced_floor(seconds)
    except (OSError, RuntimeError) as exc:
        return {'error': str(exc)}


def _stop(process: subprocess.Popen, timeout: float) -> None:
    """SIGINT the process group of ``process``, then SIGKILL it after ``timeout``."""
    for sig, wait in ((signal.SIGINT, timeout), (signal.SIGKILL, 10.0)):
        if process.poll() is not None:
            return
        try:
            os.killpg(process.pid, sig)
        except ProcessLookupError:
            return
        try:
            process.wait(wait)
        except subprocess.TimeoutExpired:
            pass


def run_soak(args: argparse.Namespace, directory: str) -> Dict[str, object]:
    """Run the twin and the controller for ``args.duration`` seconds; return the figures."""
    domain, lock = claim_domain_id()
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
               ROS_DOMAIN_ID=str(domain), PYTHONUNBUFFERED='1')
    recording = os.path.join(directory, 'soak.mcap')
    floors = [floor_window(args.floor_window)]
    cpu_before = cpu_times()
    twin_log = open(os.path.join(directory, 'twin.log'), 'w+')
    twin = subprocess.Popen(
        [sys.executable, '-m', 'conveyor_twin.cli', 'run', '--mode', 'realtime', '--duration',
         '0', '--json', '--record', recording, '--markers-rate', str(args.markers_rate)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True)
    controller_log = open(os.path.join(directory, 'controller.log'), 'w+')
    controller = subprocess.Popen([sys.executable, args.controller, '--ros-args', '-p',
                                   f'pause:={args.pause!r}'], env=env,
                                  stdout=controller_log, stderr=subprocess.STDOUT,
                                  start_new_session=True)
    progress: List[Tuple[float, int, int, int]] = []  # (wall s, step, overruns, parts)

    def read_progress() -> None:
        for line in twin.stderr:
            twin_log.write(line)
            found = _PROGRESS.search(line)
            if found:
                progress.append((time.monotonic() - t0, int(found.group(1)),
                                 int(found.group(3)), int(found.group(2))))

    import threading
    t0 = time.monotonic()
    reader_thread = threading.Thread(target=read_progress, daemon=True)
    reader_thread.start()
    samples: List[Tuple[float, int, int, int]] = []  # (s, twin rss, controller rss, file size)
    loads: List[float] = []
    ended_early = None
    try:
        while time.monotonic() - t0 < args.duration:
            time.sleep(min(args.sample_period, max(0.0, args.duration
                                                   - (time.monotonic() - t0))))
            if twin.poll() is not None or controller.poll() is not None:
                ended_early = 'twin' if twin.poll() is not None else 'controller'
                break
            t = time.monotonic() - t0
            size = os.path.getsize(recording) if os.path.exists(recording) else 0
            samples.append((t, rss_bytes(twin.pid) or 0, rss_bytes(controller.pid) or 0, size))
            loads.append(os.getloadavg()[0])
            if args.verbose:
                print(f'[{t:7.1f} s] twin RSS {samples[-1][1] / MIB:.1f} MiB, controller RSS '
                      f'{samples[-1][2] / MIB:.1f} MiB, recording {size / MIB:.1f} MiB, '
                      f'overruns {progress[-1][2] if progress else "?"}, micro parts in flight '
                      f'{progress[-1][3] if progress else "?"}', flush=True)
    finally:
        _stop(controller, 10.0)
        _stop(twin, 120.0)
        out = twin.stdout.read() if twin.stdout else ''
        reader_thread.join(5.0)
        controller_log.seek(0)
        stops = controller_log.read().count('belt stop')
        controller_log.close()
    wall = time.monotonic() - t0
    steal = steal_percent(cpu_before, cpu_times())
    floors.append(floor_window(args.floor_window))
    lock.close()
    summary = None
    for line in out.splitlines():
        if line.startswith('{'):
            summary = json.loads(line)
    twin_log.seek(0)
    log_tail = twin_log.read()[-2000:]
    twin_log.close()
    figures: Dict[str, object] = {
        'duration_s': round(wall, 1), 'domain_id': domain, 'samples': len(samples),
        'stepping_from_s': round(progress[0][0], 1) if progress else None,
        'controller_pause_s': args.pause,
        'steal_percent': steal, 'controller_belt_stops': stops,
        'load_average': {'min': min(loads), 'median': float(np.median(loads)),
                         'max': max(loads)} if loads else None}
    if ended_early:
        figures['ended_early'] = ended_early
        figures['twin_log_tail'] = log_tail
    s = np.asarray(samples, float) if samples else np.zeros((0, 4))
    # the warm-up counts from the first step (start-up loads numba's kernels first)
    stepping_from = progress[0][0] if progress else 0.0
    fit = s[s[:, 0] >= stepping_from + min(args.warmup, 0.5 * (wall - stepping_from))] \
        if len(s) else s
    figures['twin_rss_mib'] = {
        'first': round(s[0, 1] / MIB, 1) if len(s) else None,
        'last': round(s[-1, 1] / MIB, 1) if len(s) else None,
        'max': round(s[:, 1].max() / MIB, 1) if len(s) else None,
        'growth_per_hour': _round(growth_per_hour(fit[:, 0], fit[:, 1] / MIB))}
    figures['controller_rss_mib'] = {
        'first': round(s[0, 2] / MIB, 1) if len(s) else None,
        'last': round(s[-1, 2] / MIB, 1) if len(s) else None,
        'growth_per_hour': _round(growth_per_hour(fit[:, 0], fit[:, 2] / MIB))}
    size = os.path.getsize(recording) if os.path.exists(recording) else 0
    figures['recording_mib'] = {'final': round(size / MIB, 1),
                                'growth_per_hour': _round(growth_per_hour(fit[:, 0],
                                                                          fit[:, 3] / MIB))}
    steps = None
    if summary is not None:
        steps = int(summary['steps'])
        figures['twin'] = {k: summary.get(k) for k in
                           ('steps', 'overruns', 'real_time_factor', 'step_time_ms',
                            'micro_entered', 'micro_left', 'micro_in_flight',
                            'rejected_commands', 'publish_failures')}
        rec = summary.get('recording') or {}
        figures['recorder'] = {'messages': rec.get('messages'), 'dropped': rec.get('dropped')}
        figures['twin_overruns_per_hour'] = round(summary['overruns'] * 3600.0 / wall, 1)
    else:
        figures['twin_log_tail'] = log_tail
    if progress:
        # (wall s, step, overruns so far, micro parts in flight), about 12 points
        figures['timeline'] = [(round(t), step, o, n) for t, step, o, n in
                               progress[::max(1, len(progress) // 12)] + progress[-1:]]
    floor_runs = [f for f in floors if f and 'overruns' in f]
    if floor_runs:
        seconds = sum(f['duration_s'] for f in floor_runs)
        figures['floor'] = {'windows': floor_runs,
                            'overruns_per_hour': round(sum(f['overruns'] for f in floor_runs)
                                                       * 3600.0 / seconds, 1)}
    elif any(floors):
        figures['floor'] = {'windows': floors}
    if os.path.exists(recording):
        check = check_recording(recording, steps)
        if summary is not None and (figures['recorder'].get('dropped') or 0):
            check['lost'].append(f"the recorder dropped {figures['recorder']['dropped']} "
                                 'messages (queue full)')
        figures['recording_check'] = check
    else:
        figures['recording_check'] = {'lost': ['no recording was written']}
    return figures


def _round(value: Optional[float]) -> Optional[float]:
    return None if value is None else round(value, 2)


def _print(f: Dict[str, object]) -> None:
    load = f.get('load_average') or {}
    print(f"soak: {f['duration_s']} s realtime (stepping from {f['stepping_from_s']} s), "
          f"default cell, in-process recording, controller stop_on_barrier (pause "
          f"{f['controller_pause_s']} s, {f['controller_belt_stops']} belt stops); domain "
          f"{f['domain_id']}; "
          f"load average {load.get('min', 0):.2f}-{load.get('max', 0):.2f} (median "
          f"{load.get('median', 0):.2f}), CPU stolen by the hypervisor {f['steal_percent']} %")
    if f.get('ended_early'):
        print(f"  the {f['ended_early']} ended early; twin log:\n{f.get('twin_log_tail', '')}")
    r, c, m = f['twin_rss_mib'], f['controller_rss_mib'], f['recording_mib']
    print(f"  twin RSS {r['first']} -> {r['last']} MiB (max {r['max']}), growth "
          f"{r['growth_per_hour']} MiB/h; controller RSS {c['first']} -> {c['last']} MiB, "
          f"growth {c['growth_per_hour']} MiB/h")
    print(f"  recording {m['final']} MiB, growth {m['growth_per_hour']} MiB/h")
    twin = f.get('twin')
    if twin:
        print(f"  twin: {twin['steps']} steps, overruns {twin['overruns']} "
              f"({f['twin_overruns_per_hour']} per hour), real-time factor "
              f"{twin['real_time_factor']:.4f}, step time p99 {twin['step_time_ms']['p99']:.3f} "
              f"ms, max {twin['step_time_ms']['max']:.3f} ms; parts entered "
              f"{twin['micro_entered']}, left {twin['micro_left']}; recorder "
              f"{f['recorder']['messages']} messages, dropped {f['recorder']['dropped']}")
    floor = f.get('floor')
    if floor and 'overruns_per_hour' in floor:
        ratio = (f"{f['twin_overruns_per_hour'] / floor['overruns_per_hour']:.2f}"
                 if twin and floor['overruns_per_hour'] else 'n/a')
        print(f"  host floor (paced C loop, {len(floor['windows'])} windows before/after): "
              f"{[w['overruns'] for w in floor['windows']]} overruns in "
              f"{[w['duration_s'] for w in floor['windows']]} s = "
              f"{floor['overruns_per_hour']} per hour; twin / floor {ratio}")
    elif floor:
        print(f"  host floor: {floor['windows']}")
    check = f['recording_check']
    for topic in PER_STEP:
        t = check.get('topics', {}).get(topic)
        if t:
            print(f"  {topic:<17} {t['messages']:>9} messages, steps {t['first_step']}-"
                  f"{t['last_step']}, gaps {t['step_gaps']}")
    print('  nothing lost' if not check['lost'] else '  LOST: ' + '; '.join(check['lost']))


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin bench soak``."""
    p = argparse.ArgumentParser(prog='conveyor-twin bench soak', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--duration', type=float, default=DEFAULT_DURATION, help='wall time [s]')
    p.add_argument('--sample-period', type=float, default=DEFAULT_SAMPLE_PERIOD, help='[s]')
    p.add_argument('--warmup', type=float, default=DEFAULT_WARMUP,
                   help='samples before this are left out of the growth fits [s]')
    p.add_argument('--floor-window', type=float, default=DEFAULT_FLOOR_WINDOW,
                   help='paced floor loop before and after the run [s] (0: none)')
    p.add_argument('--markers-rate', type=float, default=30.0, help="the twin's markers [Hz]")
    p.add_argument('--controller', default=default_controller(),
                   help='controller script run as its own process')
    p.add_argument('--pause', type=float, default=DEFAULT_PAUSE,
                   help="the controller's belt stop per part [s]")
    p.add_argument('--keep', default=None, metavar='DIR',
                   help='keep the recording and logs in DIR (default: a temporary directory)')
    p.add_argument('--verbose', action='store_true', help='print every sample')
    p.add_argument('--json', action='store_true', help='print one JSON object')
    args = p.parse_args(argv)
    if not os.path.exists(args.controller):
        print(f'bench soak: no controller at {args.controller} (--controller)', file=sys.stderr)
        return 2
    if args.keep:
        os.makedirs(args.keep, exist_ok=True)
        figures = run_soak(args, args.keep)
    else:
        with tempfile.TemporaryDirectory() as directory:
            figures = run_soak(args, directory)
    if args.json:
        print(json.dumps(figures))
    else:
        _print(figures)
    return 0 if not figures['recording_check']['lost'] and not figures.get('ended_early') \
        else 1


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
