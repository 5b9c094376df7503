"""``conveyor-twin bench plc``: the cost and the reach of the PLC servers at 1 kHz.

Every round runs the default cell in realtime three times, interleaved: without a server,
with the OPC UA server and one subscribed client, with the Modbus TCP server and one polling
client. The twin is the coordinator core with its stages and its per-step output (no ROS
nodes: the figures isolate what the servers add); the client is another process
(``python -m conveyor_twin.bench.plc --client ...``), as a PLC is another machine. Figures:

- OPC UA: values per second delivered to the client, subscribed to every tag (publishing
  interval :data:`OPCUA_PUBLISH_MS`);
- Modbus: polls per second served (one poll: every input register and discrete input, every
  ``--poll`` seconds; 0: as fast as the client can);
- write-to-belt latency: from a client's write of the main belt's ``SpeedSetpoint`` (every
  :data:`WRITE_PERIOD` s, from :data:`WRITE_SETTLE` s into the window) to the end of the
  step whose ``belt_states`` shows it (median, p99) [ms]; client and twin read the same
  monotonic clock;
- the realtime step time (mean, median, p99) and overruns of each variant, and its ratios to
  the variant without a server (target: at most 1.10, i.e. 10 % slower).

Timings on a shared machine are noisy: compare the ratios of interleaved rounds, and rerun on
a quiet machine for published figures (docs/benchmarks.md, "PLC servers").
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import threading
import time
from types import SimpleNamespace
from typing import Any, Dict, List

DEFAULT_DURATION = 10.0   # s of realtime stepping per window
DEFAULT_ROUNDS = 3
DEFAULT_POLL = 0.01       # s between two Modbus polls of the client (a 10 ms PLC scan)
OPCUA_PUBLISH_MS = 10     # the client's subscription's publishing interval [ms]
WRITE_PERIOD = 0.1        # s between two setpoint writes of a client
WRITE_SETTLE = 0.5        # s into the window before the first write (the stepping has begun)
WRITE_VALUES = (0.5, 0.75)  # m/s, alternated (both exact in float32)
VARIANTS = ('none', 'opcua', 'modbus')
READY = 'READY'
RESULT_PREFIX = 'RESULT '
#: Longest wait for a client to connect, and for its result after the window [s].
CLIENT_TIMEOUT = 60.0


class CommandTimes:
    """A frame sink noting when each accepted command took effect (bench instrument: it costs
    a frame attribute read per step and a clock read per step with commands)."""

    def __init__(self) -> None:
        self.log: List[tuple] = []

    def on_frame(self, frame: Any) -> None:
        if frame.commands:
            now = time.monotonic_ns()
            self.log.extend((now, c.sender) for c in frame.commands)


def _twin(seed: int) -> SimpleNamespace:
    """Build the default cell's twin core with its output, as the composed layout does."""
    from conveyor_twin.cell import load_cell
    from conveyor_twin.coord.assembly import build_twin
    from conveyor_twin.output.hub import TwinOutput
    from conveyor_twin.output.producers import CoordinatorOutput, MacroOutput, MicroOutput
    cell = load_cell()
    assembled = build_twin(cell, seed=seed)
    twin = assembled.twin
    output = TwinOutput([CoordinatorOutput(twin, diagnostics=lambda t: None),
                         MicroOutput(assembled.micro), MacroOutput(assembled.macro)])
    output.health = twin.health
    twin.step_listeners.append(output.on_step)
    return SimpleNamespace(cell=cell, twin=twin, output=output, health=twin.health,
                           counters=None, runner=None)


def run_window(variant: str, *, duration: float, poll: float, warm_up: bool,
               seed: int = 1) -> Dict[str, Any]:
    """Run one realtime window of ``variant`` (``none``, ``opcua``, ``modbus``); return its
    figures."""
    from conveyor_twin.coord.runner import (raise_threads, realtime_priority, Runner,
                                            thread_ids)
    from conveyor_twin.coord.timing import TimeMode
    from conveyor_twin.plc.attach import attach_plc
    from conveyor_twin.plc.options import PlcOptions
    foreign = thread_ids()
    composed = _twin(seed)
    steps = int(round(duration / composed.cell.settings.step))
    composed.runner = runner = Runner(composed.twin, TimeMode.REALTIME, max_steps=steps)
    runner.warm_up = warm_up
    times = CommandTimes()
    servers = client = None
    figures: Dict[str, Any] = {'variant': variant}
    try:
        if variant != 'none':
            options = PlcOptions(opcua='127.0.0.1:0' if variant == 'opcua' else '',
                                 modbus='127.0.0.1:0' if variant == 'modbus' else '',
                                 security='None')
            servers = attach_plc(composed, options)
            composed.output.subscribe(times)
            target = servers.opcua_url if variant == 'opcua' else str(servers.modbus_port)
            client = _start_client(variant, target, duration, poll)
        raise_threads(thread_ids() - foreign, realtime_priority(helper=True))
        runner.start()
        runner.wait()
        if runner.error is not None:
            raise RuntimeError(f'the stepping thread failed: {runner.error!r}')
        total = runner.stats.total()
        figures.update(step_mean_ms=total['mean_ms'], step_p50_ms=total['p50_ms'],
                       step_p99_ms=total['p99_ms'], step_max_ms=total['max_ms'],
                       overruns=runner.overruns, steps=runner.steps_done,
                       realtime_priority=runner.priority)
        if client is not None:
            result = _client_result(client)
            figures.update(_client_figures(variant, result, times.log))
        failures = composed.health.summary()
        if failures:
            figures['failures'] = failures
    finally:
        runner.stop()
        if client is not None and client.poll() is None:
            client.kill()
            client.wait(10)
        if servers is not None:
            servers.stop()
    return figures


def _start_client(variant: str, target: str, duration: float,
                  poll: float) -> subprocess.Popen:
    process = subprocess.Popen(
        [sys.executable, '-m', 'conveyor_twin.bench.plc', '--client', variant, target,
         '--duration', repr(duration), '--poll', repr(poll)],
        stdout=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    deadline = time.monotonic() + CLIENT_TIMEOUT
    line = ''
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line or line.strip() == READY:
            break
    if line.strip() != READY:
        process.kill()
        raise RuntimeError(f'the {variant} client did not connect (exit {process.wait(10)})')
    return process


def _client_result(process: subprocess.Popen) -> Dict[str, Any]:
    result: List[Dict[str, Any]] = []

    def read() -> None:
        for line in process.stdout:
            if line.startswith(RESULT_PREFIX):
                result.append(json.loads(line[len(RESULT_PREFIX):]))
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(CLIENT_TIMEOUT)
    process.wait(CLIENT_TIMEOUT)
    if not result:
        raise RuntimeError(f'the client ended without a result (exit {process.returncode})')
    return result[0]


def _client_figures(variant: str, result: Dict[str, Any], applied: List[tuple]) -> Dict:
    """The client's rate and the write-to-belt latencies (the i-th write of the client pairs
    with the i-th command of its protocol that took effect)."""
    seconds = max(result['seconds'], 1e-9)
    out: Dict[str, Any] = {'client_seconds': seconds}
    if variant == 'opcua':
        out['values_per_s'] = result['count'] / seconds
    else:
        out['polls_per_s'] = result['count'] / seconds
    mine = [t for t, sender in applied if sender.startswith(variant)]
    latencies = sorted((a - w) * 1e-6 for w, a in zip(result['writes'], mine))
    out['writes'] = len(result['writes'])
    out['writes_applied'] = len(mine)
    if latencies:
        out['latency_p50_ms'] = statistics.median(latencies)
        out['latency_p99_ms'] = latencies[min(len(latencies) - 1,
                                              int(round(0.99 * (len(latencies) - 1))))]
    return out


def summarize(windows: List[Dict[str, Any]]) -> Dict[str, Any]:
    """Per variant: the median over rounds of each figure, and the step-time ratios to the
    variant without a server (median over rounds of the per-round ratios)."""
    out: Dict[str, Any] = {}
    keys = ('step_mean_ms', 'step_p50_ms', 'step_p99_ms', 'overruns', 'values_per_s',
            'polls_per_s', 'latency_p50_ms', 'latency_p99_ms')
    for variant in VARIANTS:
        mine = [w for w in windows if w['variant'] == variant and 'error' not in w]
        out[variant] = {k: statistics.median([w[k] for w in mine])
                        for k in keys if mine and all(k in w for w in mine)}
    rounds: Dict[int, Dict[str, Dict]] = {}
    for w in windows:
        rounds.setdefault(w['round'], {})[w['variant']] = w
    for variant in VARIANTS[1:]:
        for key in ('step_mean_ms', 'step_p99_ms'):
            ratios = [r[variant][key] / r['none'][key] for r in rounds.values()
                      if variant in r and 'none' in r and key in r[variant]
                      and r['none'].get(key)]
            if ratios:
                out[variant][f'{key[:-3]}_ratio'] = statistics.median(ratios)
    return out


def print_summary(summary: Dict[str, Any], rounds: int, duration: float) -> None:
    """Print one line per variant, then the ratios."""
    print(f'bench plc: {rounds} round(s) of {duration:g} s per variant, realtime at 1 kHz, '
          'default cell (noisy on a shared machine)')
    for variant in VARIANTS:
        v = summary.get(variant, {})
        if not v:
            print(f'  {variant:<7} no result')
            continue
        line = (f"  {variant:<7} step mean {v['step_mean_ms']:.4f} ms, p50 "
                f"{v['step_p50_ms']:.4f} ms, p99 {v['step_p99_ms']:.4f} ms, overruns "
                f"{v['overruns']:g}")
        if 'values_per_s' in v:
            line += f"; {v['values_per_s']:.0f} values/s to the client"
        if 'polls_per_s' in v:
            line += f"; {v['polls_per_s']:.0f} polls/s served"
        if 'latency_p50_ms' in v:
            line += (f"; write to belt p50 {v['latency_p50_ms']:.2f} ms, p99 "
                     f"{v['latency_p99_ms']:.2f} ms")
        print(line)
    for variant in VARIANTS[1:]:
        v = summary.get(variant, {})
        if 'step_mean_ratio' in v:
            verdict = 'within' if v['step_mean_ratio'] <= 1.10 else 'above'
            print(f"  {variant} / none: step mean x{v['step_mean_ratio']:.3f}, p99 "
                  f"x{v.get('step_p99_ratio', float('nan')):.3f} ({verdict} the 1.10 target)")


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin bench plc``."""
    p = argparse.ArgumentParser(prog='conveyor-twin bench plc', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--duration', type=float, default=DEFAULT_DURATION,
                   help='realtime seconds per window [s]')
    p.add_argument('--rounds', type=int, default=DEFAULT_ROUNDS,
                   help='rounds of the three variants, interleaved')
    p.add_argument('--poll', type=float, default=DEFAULT_POLL,
                   help="the Modbus client's poll period [s] (0: as fast as it can)")
    p.add_argument('--json', action='store_true', help='print the figures as one JSON object')
    args = p.parse_args(argv)
    if not args.duration > 0 or args.rounds < 1 or not args.poll >= 0:
        print(f'conveyor-twin bench plc: --duration {args.duration} must be > 0, --rounds '
              f'{args.rounds} >= 1, --poll {args.poll} >= 0', file=sys.stderr)
        return 2
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    windows: List[Dict[str, Any]] = []
    first = True
    for r in range(args.rounds):
        for variant in VARIANTS:
            try:
                w = run_window(variant, duration=args.duration, poll=args.poll, warm_up=first)
            except Exception as exc:  # noqa: BLE001 - a window without result is reported
                w = {'variant': variant, 'error': repr(exc)}
            first = False
            w['round'] = r
            windows.append(w)
            if not args.json:
                print(f'  round {r + 1} {variant}: ' + ', '.join(
                    f'{k} {v:.4g}' if isinstance(v, float) else f'{k} {v}'
                    for k, v in w.items() if k not in ('variant', 'round')), flush=True)
    summary = summarize(windows)
    if args.json:
        print(json.dumps({'duration_s': args.duration, 'rounds': args.rounds,
                          'poll_s': args.poll, 'windows': windows, 'summary': summary},
                         sort_keys=True))
    else:
        print_summary(summary, args.rounds, args.duration)
    errors = [w for w in windows if 'error' in w or 'failures' in w]
    return 1 if errors else 0


# --- the client process ----------------------------------------------------------------------

def client_main(argv: List[str]) -> int:
    """The bench's client: connect, print READY, work ``--duration`` s, print the result."""
    p = argparse.ArgumentParser(prog='python -m conveyor_twin.bench.plc --client')
    p.add_argument('--client', required=True, choices=['opcua', 'modbus'])
    p.add_argument('target', help='OPC UA url, or Modbus port on 127.0.0.1')
    p.add_argument('--duration', type=float, required=True)
    p.add_argument('--poll', type=float, default=DEFAULT_POLL)
    args = p.parse_args(argv)
    import logging
    logging.basicConfig(level=logging.ERROR)  # not asyncua's notes on revised parameters
    if args.client == 'opcua':
        import asyncio
        result = asyncio.run(_opcua_client(args.target, args.duration))
    else:
        result = _modbus_client(int(args.target), args.duration, args.poll)
    print(RESULT_PREFIX + json.dumps(result), flush=True)
    return 0


async def _opcua_client(url: str, duration: float) -> Dict[str, Any]:
    import asyncio

    from asyncua import Client, ua

    from conveyor_twin.cell import load_cell
    from conveyor_twin.plc.tags import tag_map
    counter = SimpleNamespace(count=0)

    class Handler:
        def datachange_notification(self, node: Any, value: Any, data: Any) -> None:
            counter.count += 1

    tags = [t for t in tag_map(load_cell()).tags if getattr(t, 'opcua', True)]
    async with Client(url, timeout=30) as client:
        ns = await client.get_namespace_index('urn:conveyor-twin:twin')
        nodes = [client.get_node(ua.NodeId(f'Twin/{t.path}', ns)) for t in tags]
        setpoint = client.get_node(ua.NodeId('Twin/Belts/main/SpeedSetpoint', ns))
        subscription = await client.create_subscription(OPCUA_PUBLISH_MS, Handler())
        await subscription.subscribe_data_change(nodes)
        print(READY, flush=True)
        counter.count = 0
        writes: List[int] = []
        start = time.monotonic()
        next_write = start + WRITE_SETTLE
        while time.monotonic() - start < duration:
            if time.monotonic() >= next_write:
                value = WRITE_VALUES[len(writes) % 2]
                writes.append(time.monotonic_ns())
                await setpoint.write_value(ua.DataValue(ua.Variant(value,
                                                                   ua.VariantType.Double)))
                next_write += WRITE_PERIOD
            await asyncio.sleep(min(0.01, max(0.0, next_write - time.monotonic())))
        seconds = time.monotonic() - start
        count = counter.count
    return {'count': count, 'seconds': seconds, 'writes': writes}


def _modbus_client(port: int, duration: float, poll: float) -> Dict[str, Any]:
    from pymodbus.client import ModbusTcpClient

    from conveyor_twin.cell import load_cell
    from conveyor_twin.plc.tags import modbus_words, tag_map
    tags = tag_map(load_cell())
    setpoint = tags.by_path('Belts/main/SpeedSetpoint')
    inputs, discrete = tags.modbus_size('input'), tags.modbus_size('discrete')
    client = ModbusTcpClient('127.0.0.1', port=port, timeout=30)
    if not client.connect():
        raise SystemExit(f'no Modbus server at 127.0.0.1:{port}')
    print(READY, flush=True)
    polls = 0
    writes: List[int] = []
    start = time.monotonic()
    next_poll, next_write = start, start + WRITE_SETTLE
    try:
        while time.monotonic() - start < duration:
            now = time.monotonic()
            if now >= next_write:
                words = list(modbus_words(setpoint, WRITE_VALUES[len(writes) % 2]))
                writes.append(time.monotonic_ns())
                client.write_registers(setpoint.modbus_address, words)
                next_write += WRITE_PERIOD
            if now >= next_poll:
                for first in range(0, inputs, 120):
                    client.read_input_registers(first, count=min(120, inputs - first))
                client.read_discrete_inputs(0, count=discrete)
                polls += 1
                next_poll = max(next_poll + poll, time.monotonic()) if poll else 0.0
            if poll:
                time.sleep(max(0.0, min(next_poll, next_write) - time.monotonic()))
        seconds = time.monotonic() - start
    finally:
        client.close()
    return {'count': polls, 'seconds': seconds, 'writes': writes}


if __name__ == '__main__':
    sys.exit(client_main(sys.argv[1:]))
