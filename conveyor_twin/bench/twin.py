"""``conveyor-twin bench twin``: the node suite at 1 kHz, measured from another process.

The twin (``conveyor-twin run``, realtime, composed by default or ``--split``) runs on the
default cell without its feeder; a separate subscriber process (raw subscriptions, rclpy's
EventsExecutor) places ``--parts`` parts on the belt through ``spawn_parts`` (a lattice over
x 0.3-3 m), sets the belt to ``--belt-speed`` so they are conveyed but stay on the belt for the
run, lets ``--settle`` seconds pass, then measures for ``--duration`` seconds:

- per stream: messages, rate [Hz], inter-arrival p50/p99/max [ms], lost messages (gaps in the
  sim-time stamps, which advance one step per message);
- the subscriber's own CPU time per second of the window.

Readers (``--reader``): ``poll`` (default) takes every queued message of every stream every
``POLL_PERIOD`` in one pass and times it by its DDS reception time (``received_timestamp``,
stamped by the middleware's receive thread when the sample arrives), so the measuring process
costs little CPU on a 2-core machine and its own Python scheduling does not enter the
inter-arrival figures; ``callback`` runs one rclpy callback per message (EventsExecutor) and
times it on arrival in Python, as a controller written with callbacks would see the streams.
Both readers keep 1000 samples per stream, so "lost" counts what the twin did not deliver;
the measuring process runs under SCHED_FIFO (``--reader-priority``, below the twin's threads)
where permitted, so that other work on a loaded machine does not make it fall 100 messages
behind the twin's reliable streams (their history) or miss best-effort ``/clock`` samples.
- overruns and step times from the twin's ``diagnostics`` (1 Hz) during the window, and the
  twin's closing summary; where the late steps come from: every second with an overrun,
  counted by its slowest step: started late (even that step fit in 1 ms: a late step began
  after its deadline, the thread resumed late, ``latest_wake_ms``), waiting for the CPU (the
  stepping thread ran for less than half of it), or the part of the step that took most of it
  (``slowest_step_parts_ms``: commands, each stage, outputs).

The host's floor (``bench host``: a C loop paced exactly like the twin's stepping thread, doing
no work) runs for ``--floor-window`` seconds before the first twin window and after every twin
window, so floor and twin windows interleave; the twin's overruns per minute are reported as a
ratio to those of the floor windows beside it (1: the twin loses no deadline the machine would
have kept; the floor's own overruns are time the kernel or the hypervisor took from any loop).

``--rounds N`` repeats the twin windows (each with its floor windows around it) and ends with
a summary per layout or variant: the twin/floor ratio of every round and their median, the
messages lost per stream in all rounds, and the machine's load average (1 min) during each
window. The twin and its subscriber run in a ROS domain of their own (claimed like the test
suite's), so another twin on the machine cannot mix into the figures.

``--foxglove``: every round runs the composed twin three times side by side: without a
Foxglove view, with a view no client watches, and with a view and one client
(:mod:`conveyor_twin.bench.foxglove_client`, another process) subscribed to every channel; it
prints the step-time and stream figures of the three and their ratios to the first.

Targets: 0 overruns beyond the floor, >= 999 Hz per stream, p99 <= 1.5 ms, no loss.
"""

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from typing import Dict, List, Optional

import numpy as np

from conveyor_twin.bench.cpu import cpu_times, steal_percent
from conveyor_twin.bench.twin_rounds import print_rounds, rounds_summary, STEP_NS, STREAMS
from conveyor_twin.bench.twin_window import window_figures

DEFAULT_DURATION = 60.0   # s measured
DEFAULT_PARTS = 1000
DEFAULT_SETTLE = 3.0      # s between placing the parts and measuring
DEFAULT_BELT_SPEED = 0.05  # m/s: 1000 parts stay on the 6 m belt for a minute
CONNECT_TIMEOUT = 60.0    # s for the twin to appear
STEPPING_TIMEOUT = 300.0  # s for it to step (a realtime twin loads its kernels first)
RESULT_PREFIX = 'bench twin subscriber: '
POLL_PERIOD = 0.002   # s between two passes of the polling reader
READER_DEPTH = 1000    # samples each reader keeps
#: SCHED_FIFO priority of the measuring process: below the twin's stepping (10) and helper
#: (9) threads; it polls every 2 ms and uses about a tenth of a core.
READER_PRIORITY = 5


def lattice(n: int, *, x0: float = 0.3, y_half: float = 0.2, pitch_y: float = 0.04,
            pitch_x: float = 0.03) -> np.ndarray:
    """Return (x, y) of ``n`` parts on a lattice over the belt [m]."""
    rows = int(2 * y_half / pitch_y) + 1
    k = np.arange(n)
    x = x0 + (k // rows) * pitch_x
    y = -y_half + (k % rows) * pitch_y
    return np.stack([x, y])


def free_places(xy: np.ndarray, part_type: str = 'spacer') -> np.ndarray:
    """Return the places of ``xy`` (2 x n) where a part of ``part_type`` may be spawned on the
    default cell: on a belt, clear of every wall, deflector and peg."""
    from conveyor_twin.cell import load_cell
    from conveyor_twin.coord.requests import placement_problem
    cell = load_cell(None)
    radius = cell.part_types[cell.part_type_index(part_type)].bounding_radius
    keep = [not placement_problem(cell, float(x), float(y), radius) for x, y in xy.T]
    return xy[:, np.asarray(keep, bool)]


def refused_entries(message: str) -> List[int]:
    """Return the indices of the request's entries a refused ``spawn_parts`` names: ``entries
    [i, j]`` (overlapping parts) or ``part i (...)`` (a static obstacle); [] if none."""
    listed = re.search(r'entries \[([0-9, ]+)\]', message)
    if listed is not None:
        return [int(i) for i in listed.group(1).split(',')]
    single = re.match(r'part (\d+) \(', message)
    return [int(single.group(1))] if single is not None else []


def quiet_cell_file(directory: str) -> str:
    """Write the default cell without its feeder; return the file."""
    import yaml

    from conveyor_twin.cell import default_cell_text
    doc = yaml.safe_load(default_cell_text())
    doc['sources'] = []
    path = os.path.join(directory, 'bench_twin_cell.yaml')
    with open(path, 'w') as f:
        yaml.safe_dump(doc, f)
    return path


def _stats(times_ns: List[int], stamps_ns: List[int], window_s: float,
           step_ns: int = STEP_NS) -> Dict[str, float]:
    if len(times_ns) < 2:
        return {'messages': len(times_ns)}
    t = np.asarray(times_ns, np.int64)
    s = np.asarray(stamps_ns, np.int64)
    gaps = np.diff(t) * 1e-6
    steps = np.diff(s) // step_ns
    lost = int(np.sum(np.maximum(steps - 1, 0)))
    return {'messages': len(t), 'rate_hz': round(len(t) / window_s, 2),
            'interarrival_p50_ms': round(float(np.median(gaps)), 4),
            'interarrival_p99_ms': round(float(np.percentile(gaps, 99)), 4),
            'interarrival_max_ms': round(float(gaps.max()), 4),
            'lost': lost, 'out_of_order': int(np.sum(steps <= 0))}


def subscriber_main(argv: List[str]) -> int:
    """The measuring process: place the parts, then record arrivals of every stream."""
    p = argparse.ArgumentParser()
    p.add_argument('--parts', type=int, default=DEFAULT_PARTS)
    p.add_argument('--duration', type=float, default=DEFAULT_DURATION)
    p.add_argument('--settle', type=float, default=DEFAULT_SETTLE)
    p.add_argument('--belt-speed', type=float, default=DEFAULT_BELT_SPEED)
    p.add_argument('--reader', choices=('poll', 'callback'), default='poll')
    p.add_argument('--priority', type=int, default=0)
    args = p.parse_args(argv)
    if args.priority > 0:  # before any thread starts: the middleware's threads inherit it
        from conveyor_twin.coord.runner import raise_thread_priority
        raise_thread_priority(args.priority)

    import rclpy
    from rclpy.context import Context
    from rclpy.experimental import EventsExecutor
    from rclpy.node import Node
    from conveyor_twin_msgs.msg import (ActuatorStates, BeltCommand, BeltStates,
                                        LightBarrierStates, PartStates)
    from conveyor_twin_msgs.srv import SpawnParts
    from diagnostic_msgs.msg import DiagnosticArray
    from rosgraph_msgs.msg import Clock

    from rclpy.qos import QoSProfile

    from conveyor_twin.coord.runner import freeze_heap
    from conveyor_twin import contract
    from conveyor_twin.ros.qos import CLOCK_QOS, COMMAND_QOS, SLOW_QOS, STREAM_QOS

    types = {contract.PARTS.name: PartStates, contract.LIGHT_BARRIERS.name: LightBarrierStates,
             contract.BELT_STATES.name: BeltStates,
             contract.ACTUATOR_STATES.name: ActuatorStates, contract.CLOCK.name: Clock}
    context = Context()
    rclpy.init(context=context)
    node = Node('bench_twin_subscriber', context=context)
    executor = EventsExecutor(context=context)
    executor.add_node(node)
    recording = [False]
    arrivals = {t: ([], []) for t in STREAMS}
    diagnostics: List[Dict[str, str]] = []

    seen = {t: 0 for t in STREAMS}  # samples taken per stream (does the twin step yet?)

    def on_raw(data: bytes, log, topic: str = '') -> None:
        seen[topic] = seen.get(topic, 0) + 1
        if recording[0]:
            log[0].append(time.monotonic_ns())
            log[1].append(int.from_bytes(data[4:8], 'little') * 1_000_000_000
                          + int.from_bytes(data[8:12], 'little'))

    # /clock is offered best-effort, keep-last 1 (the simulator convention); a clock consumer
    # subscribes with depth 1 and wants only the newest. Here every reader keeps 1000 so that
    # "lost" counts what the twin did not deliver, not what this reader overwrote.
    def reader_qos(topic: str) -> QoSProfile:
        offered = CLOCK_QOS if topic == contract.CLOCK.name else STREAM_QOS
        return QoSProfile(depth=READER_DEPTH, reliability=offered.reliability,
                          durability=offered.durability)

    # the polling reader's subscriptions belong to a node no executor serves: only take() reads
    readers = Node('bench_twin_reader', context=context) if args.reader == 'poll' else node
    subs = [readers.create_subscription(types[t], t,
                                        lambda d, log=arrivals[t], t=t: on_raw(d, log, t),
                                        reader_qos(t), raw=True)
            for t in STREAMS]
    polled = (list(zip(subs, STREAMS, (arrivals[t] for t in STREAMS)))
              if args.reader == 'poll' else [])

    def take_all() -> None:
        """Take every queued sample of every stream; time it by its DDS reception."""
        for sub, topic, log in polled:
            handle, msg_type = sub.handle, sub.msg_type
            while True:
                taken = handle.take_message(msg_type, True)
                if taken is None:
                    break
                seen[topic] += 1
                if recording[0]:
                    data, info = taken
                    log[0].append(info['received_timestamp'])
                    log[1].append(int.from_bytes(data[4:8], 'little') * 1_000_000_000
                                  + int.from_bytes(data[8:12], 'little'))
    subs.append(node.create_subscription(
        DiagnosticArray, contract.DIAGNOSTICS.name,
        lambda m: diagnostics.append({kv.key: kv.value for kv in m.status[0].values}),
        SLOW_QOS))
    spawn = node.create_client(SpawnParts, contract.SPAWN_PARTS.name)
    belt = node.create_publisher(BeltCommand, contract.BELT_COMMAND.name, COMMAND_QOS)

    def spin_for(seconds: float, until=lambda: False) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if until():
                return True
            executor.spin_once(timeout_sec=POLL_PERIOD if polled else 0.05)
            take_all()
        return until()

    ok = spin_for(CONNECT_TIMEOUT, lambda: spawn.service_is_ready()
                  and belt.get_subscription_count() > 0
                  and all(s.get_publisher_count() > 0 for s in subs))
    if not ok:
        print('bench twin: the twin did not appear', file=sys.stderr)
        return 1
    from rclpy.duration import Duration
    belt.publish(BeltCommand(belt='main', speed=args.belt_speed))
    belt.wait_for_all_acked(Duration(seconds=10))
    placed = 0
    xy = free_places(lattice(2 * args.parts))  # spare places: some hit the deflector
    start = 0
    while placed < args.parts and start < xy.shape[1]:
        # a few calls of up to 250 parts; each places its parts at one step boundary
        chunk = xy[:, start:start + min(250, args.parts - placed)]
        start += chunk.shape[1]
        keep = np.ones(chunk.shape[1], bool)
        for _ in range(10):  # drop the places the twin refuses (overlaps) and try again
            future = spawn.call_async(SpawnParts.Request(
                part_type='spacer', x=chunk[0, keep].tolist(), y=chunk[1, keep].tolist(),
                yaw=[0.0] * int(keep.sum())))
            spin_for(30.0, future.done)
            response = future.result() if future.done() else None
            if response is not None and response.success:
                placed += len(response.id)
                break
            refused = refused_entries(response.message if response else '')
            if not refused:
                print(f'bench twin: spawn failed: {response}', file=sys.stderr)
                break
            keep[np.flatnonzero(keep)[refused]] = False
    # the twin serves its services before it steps (a realtime twin first loads its kernels):
    # measure only once every stream flows
    seen.update({t: 0 for t in STREAMS})
    if not spin_for(STEPPING_TIMEOUT, lambda: all(seen.values())):
        print(f'bench twin: the twin did not publish every stream within {STEPPING_TIMEOUT:g} '
              f's: {seen}', file=sys.stderr)
        return 1
    freeze_heap()  # no full collections of this process's heap during the window
    spin_for(args.settle)
    take_all()  # what queued before the window is not measured
    diagnostics.clear()
    recording[0] = True
    t0 = time.monotonic()
    cpu0 = time.process_time()
    spin_for(args.duration)
    take_all()
    recording[0] = False
    window = time.monotonic() - t0
    cpu = time.process_time() - cpu0
    streams = {t: _stats(a[0], a[1], window) for t, a in arrivals.items()}
    result = {'placed_parts': placed, 'window_s': round(window, 3), 'streams': streams,
              'reader': args.reader, 'subscriber_cpu_share': round(cpu / window, 3),
              'diagnostics': diagnostics}
    print(RESULT_PREFIX + json.dumps(result), flush=True)
    executor.shutdown(timeout_sec=2.0)
    if readers is not node:
        readers.destroy_node()
    node.destroy_node()
    context.try_shutdown()
    return 0


def _signal_group(pid: int, sig: int) -> None:
    """Send ``sig`` to the twin's process group, if anything of it is left."""
    try:
        os.killpg(pid, sig)
    except ProcessLookupError:
        pass


def _free_port() -> int:
    import socket
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def run_layout(split: bool, args: argparse.Namespace, directory: str,
               foxglove: str = '') -> Dict[str, object]:
    """Run the twin in one layout and the subscriber process; return the figures.

    :param foxglove: ``view``: the twin serves a Foxglove view nobody watches; ``client``: and
        a client process reads every channel of it; empty: no view.

    ``steal_percent``: CPU time taken by the hypervisor for other guests during the run (on a
    virtual machine the twin cannot be scheduled then, whatever its priority).
    """
    cpu_before = cpu_times()
    env = dict(os.environ)
    env.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if getattr(args, 'domain_id', None) is not None:
        env['ROS_DOMAIN_ID'] = str(args.domain_id)
    cell = quiet_cell_file(directory)
    twin_cmd = [sys.executable, '-m', 'conveyor_twin.cli', 'run', '--cell', cell,
                '--mode', 'realtime', '--duration', '0', '--json', '--quiet',
                '--markers-rate', str(args.markers_rate)]
    if split:
        twin_cmd.append('--split')
    client = None
    if foxglove:
        port = _free_port()
        twin_cmd += ['--foxglove', f'127.0.0.1:{port}']
    twin_log = open(os.path.join(directory, 'twin.log'), 'w+')
    twin = subprocess.Popen(twin_cmd, env=env, stdout=subprocess.PIPE, stderr=twin_log,
                            text=True, start_new_session=True)
    sub = subprocess.Popen(
        [sys.executable, '-m', 'conveyor_twin.bench.twin', '--subscriber', '--parts',
         str(args.parts), '--duration', str(args.duration), '--settle', str(args.settle),
         '--belt-speed', str(args.belt_speed), '--reader', args.reader, '--priority',
         str(args.reader_priority)], env=env,
        stdout=subprocess.PIPE, text=True)
    if foxglove == 'client':
        client = subprocess.Popen([sys.executable, '-m', 'conveyor_twin.bench.foxglove_client',
                                   str(port)], env=env, stdout=subprocess.PIPE, text=True)
    result: Optional[dict] = None
    client_result: Optional[dict] = None
    try:
        for line in sub.stdout:
            if line.startswith(RESULT_PREFIX):
                result = json.loads(line[len(RESULT_PREFIX):])
        sub.wait(60)
    finally:
        if client is not None:
            client.send_signal(signal.SIGINT)
            try:
                client_out, _ = client.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                client.kill()
                client_out, _ = client.communicate()
            from conveyor_twin.bench.foxglove_client import RESULT_PREFIX as CLIENT_PREFIX
            for line in client_out.splitlines():
                if line.startswith(CLIENT_PREFIX):
                    client_result = json.loads(line[len(CLIENT_PREFIX):])
        ended_early = twin.poll() is not None
        _signal_group(twin.pid, signal.SIGINT)
        try:
            out, _ = twin.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            _signal_group(twin.pid, signal.SIGKILL)
            out, _ = twin.communicate()
    summary = None
    for line in out.splitlines():
        if line.startswith('{'):
            summary = json.loads(line)
    figures: Dict[str, object] = {'layout': 'split' if split else 'composed',
                                  'steal_percent': steal_percent(cpu_before, cpu_times()),
                                  'load_average': round(os.getloadavg()[0], 2)}
    if foxglove:
        figures['foxglove'] = foxglove
        if client is not None:
            figures['foxglove_client'] = client_result
    twin_log.seek(0)
    log = twin_log.read()
    twin_log.close()
    if ended_early or 'error' in log.lower() or result is None:
        figures['twin_ended_early'] = ended_early
        figures['twin_log_tail'] = log[-2000:]
    if result is None:
        figures['error'] = 'the subscriber process gave no result'
        return figures
    figures.update({k: v for k, v in result.items() if k != 'diagnostics'})
    figures.update(window_figures(result['diagnostics']))
    if summary is not None:
        figures['twin_summary'] = {k: summary.get(k) for k in
                                   ('steps', 'overruns', 'real_time_factor', 'step_time_ms',
                                    'publish_failures')}
    return figures


def floor_figures(window: Optional[Dict[str, object]]) -> Optional[Dict[str, object]]:
    """Run the paced floor loop for a window of ``window['seconds']``; None without one."""
    if not window or window.get('seconds', 0) <= 0:
        return None
    from conveyor_twin.bench.host import paced_floor
    try:
        out = paced_floor(float(window['seconds']))
        if window.get('work_ms'):   # then the same loop working as long as a step, after it
            out['working'] = paced_floor(float(window['seconds']),
                                         work_ns=int(round(float(window['work_ms']) * 1e6)))
        return out
    except RuntimeError as exc:
        return {'error': str(exc)}


def compare_to_floor(figures: Dict[str, object], before: Optional[Dict[str, object]],
                     after: Optional[Dict[str, object]]) -> None:
    """Add the floor windows around a twin window and the ratio of overrun rates to ``figures``.

    ``overruns_vs_floor``: (twin overruns per minute) / (floor overruns per minute of the
    windows before and after); None when the floor saw no overrun (then compare counts).
    """
    windows = [w for w in (before, after) if w and 'overruns' in w]
    figures['floor'] = {'windows': [w for w in (before, after) if w]}
    if not windows or 'overruns_in_window' not in figures:
        return
    floor_rate = (sum(int(w['overruns']) for w in windows) * 60.0
                  / sum(float(w['duration_s']) for w in windows))
    twin_rate = int(figures['overruns_in_window']) * 60.0 / float(figures['window_s'])
    figures['floor']['overruns_per_min'] = round(floor_rate, 2)
    figures['overruns_per_min'] = round(twin_rate, 2)
    figures['overruns_vs_floor'] = round(twin_rate / floor_rate, 2) if floor_rate else None
    working = [w['working'] for w in windows if 'working' in w]
    if working:
        rate = (sum(int(w['overruns']) for w in working) * 60.0
                / sum(float(w['duration_s']) for w in working))
        figures['floor']['working_overruns_per_min'] = round(rate, 2)
        figures['floor']['working_work_ms'] = round(int(working[0]['work_ns']) * 1e-6, 3)
        figures['overruns_vs_working_floor'] = round(twin_rate / rate, 2) if rate else None


def foxglove_comparison(results: List[Dict[str, object]]) -> Dict[str, object]:
    """Return the median step-time mean of each ``--foxglove`` variant and its ratio to the
    runs without a view [ms, 1]."""
    by_variant: Dict[str, List[float]] = {}
    for figures in results:
        mean = figures.get('step_time_mean_ms_median')
        if mean is not None:
            by_variant.setdefault(str(figures.get('foxglove') or 'none'), []).append(
                float(mean))
    medians = {variant: float(np.median(v)) for variant, v in by_variant.items()}
    base = medians.get('none')
    return {'step_time_mean_ms': medians,
            'ratio_to_none': {variant: round(m / base, 3) for variant, m in medians.items()}
            if base else {}}


def _print(figures: Dict[str, object]) -> None:
    variant = f" (Foxglove: {figures['foxglove']})" if figures.get('foxglove') else ''
    print(f"{figures['layout']}{variant}: {figures.get('placed_parts')} parts placed, window "
          f"{figures.get('window_s')} s, micro parts in flight "
          f"{figures.get('micro_in_flight')}, CPU stolen by the hypervisor "
          f"{figures.get('steal_percent')} %, load average {figures.get('load_average')}; "
          f"{figures.get('reader')} reader using {figures.get('subscriber_cpu_share')} of a core")
    if 'error' in figures:
        print(f"  error: {figures['error']}")
        return
    for topic, s in figures['streams'].items():
        if 'rate_hz' not in s:
            print(f'  {topic:<16} {s}')
            continue
        print(f"  {topic:<16} {s['rate_hz']:8.1f} Hz  inter-arrival p50 "
              f"{s['interarrival_p50_ms']:.3f} p99 {s['interarrival_p99_ms']:.3f} max "
              f"{s['interarrival_max_ms']:.1f} ms  lost {s['lost']}")
    print(f"  overruns in window {figures.get('overruns_in_window')}; step time mean "
          f"(median of 1 s windows) {figures.get('step_time_mean_ms_median')} ms, p99 (worst "
          f"window) {figures.get('step_time_p99_ms_max')} ms, max "
          f"{figures.get('step_time_max_ms_max')} ms")
    if figures.get('slowest_step_parts_ms'):
        print(f"  where the late steps come from (seconds with an overrun, by their slowest "
              f"step): {figures.get('late_seconds_by_cause')}; slowest step "
              f"{figures.get('slowest_step_ms')} ms ({figures.get('slowest_step_parts_ms')} ms; "
              f"CPU {figures.get('slowest_step_cpu_ms')} ms); latest wake-up "
              f"{figures.get('latest_wake_ms')} ms after its deadline")
    floor = figures.get('floor') or {}
    if floor.get('windows'):
        counts = [w.get('overruns', w.get('error')) for w in floor['windows']]
        ratio = figures.get('overruns_vs_floor')
        print(f"  host floor (paced C loop, {floor['windows'][0].get('policy')}, latency request "
              f"{floor['windows'][0].get('latency_request')}) before/after: "
              f"{counts} overruns in {[w.get('duration_s') for w in floor['windows']]} s = "
              f"{floor.get('overruns_per_min')} per min; twin {figures.get('overruns_per_min')} "
              f"per min; twin / floor "
              f"{ratio if ratio is not None else 'n/a (the floor saw no overrun)'}")
        if 'working_overruns_per_min' in floor:
            print(f"  the floor loop working {floor['working_work_ms']} ms per step: "
                  f"{floor['working_overruns_per_min']} overruns per min; twin / working floor "
                  f"{figures.get('overruns_vs_working_floor', 'n/a')}")
    print(f"  twin summary: {figures.get('twin_summary')}")
    if 'foxglove_client' in figures:
        print(f"  Foxglove client: {figures['foxglove_client']}")
    if 'twin_log_tail' in figures:
        print(f"  twin ended early: {figures['twin_ended_early']}; its log ends:\n"
              + figures['twin_log_tail'])


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin bench twin``."""
    if argv[:1] == ['--subscriber']:
        return subscriber_main(argv[1:])
    p = argparse.ArgumentParser(prog='conveyor-twin bench twin', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--duration', type=float, default=DEFAULT_DURATION,
                   help='measured wall time [s]')
    p.add_argument('--parts', type=int, default=DEFAULT_PARTS)
    p.add_argument('--settle', type=float, default=DEFAULT_SETTLE,
                   help='wait after placing the parts [s]')
    p.add_argument('--belt-speed', type=float, default=DEFAULT_BELT_SPEED, help='[m/s]')
    p.add_argument('--layout', choices=('composed', 'split', 'both'), default='composed')
    p.add_argument('--reader', choices=('poll', 'callback'), default='poll',
                   help='poll: take all queued samples every 2 ms, timed by DDS reception; '
                        'callback: one rclpy callback per message, timed in Python')
    p.add_argument('--reader-priority', type=int, default=READER_PRIORITY,
                   help='SCHED_FIFO priority of the measuring process, below the twin\'s '
                        'threads, so that other work on the machine cannot make it miss '
                        'messages the twin sent (0: normal scheduling)')
    p.add_argument('--markers-rate', type=float, default=30.0,
                   help="the twin's MarkerArray rate [Hz] (0: none)")
    p.add_argument('--floor-window', type=float, default=30.0,
                   help='paced floor loop before the first and after every twin window [s] '
                        '(0: none)')
    p.add_argument('--floor-work-ms', type=float, default=0.0,
                   help='after each floor window, one of the floor loop doing this much '
                        'computation per step [ms] (e.g. the step time; 0: none)')
    p.add_argument('--rounds', type=int, default=1, help='twin windows per layout')
    p.add_argument('--foxglove', action='store_true',
                   help='composed twin without a Foxglove view, with a view and no client, '
                        'and with one client reading every channel, side by side per round')
    p.add_argument('--json', action='store_true', help='print one JSON object')
    args = p.parse_args(argv)
    layouts = {'composed': [(False, '')], 'split': [(True, '')],
               'both': [(False, ''), (True, '')]}[args.layout]
    if args.foxglove:
        layouts = [(False, ''), (False, 'view'), (False, 'client')]
    results = []
    if not 0.0 <= args.floor_work_ms < 1.0:
        p.error(f'--floor-work-ms: got {args.floor_work_ms:g}; expected 0 <= ms < 1')
    floor_window = {'seconds': args.floor_window, 'work_ms': args.floor_work_ms}
    from conveyor_twin.bench.soak import claim_domain_id
    args.domain_id, domain_lock = claim_domain_id()  # held until the bench ends
    with domain_lock, tempfile.TemporaryDirectory() as directory:
        before = floor_figures(floor_window)
        for _ in range(max(1, args.rounds)):
            for split, foxglove in layouts:
                figures = run_layout(split, args, directory, foxglove)
                after = floor_figures(floor_window)
                compare_to_floor(figures, before, after)
                before = after
                results.append(figures)
                if not args.json:
                    _print(figures)
    comparison = foxglove_comparison(results) if args.foxglove else None
    summary = rounds_summary(results)
    if args.json:
        print(json.dumps({'parts': args.parts, 'duration_s': args.duration,
                          'layouts': results, 'foxglove': comparison, 'rounds': summary}))
        return 0
    print_rounds(summary)
    if comparison is not None:
        means, ratios = comparison['step_time_mean_ms'], comparison['ratio_to_none']
        print('Foxglove, side by side (median over rounds of the step-time mean): '
              + ', '.join(f'{v} {means[v]:.4f} ms (ratio {ratios.get(v, "n/a")})'
                          for v in ('none', 'view', 'client') if v in means))
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
