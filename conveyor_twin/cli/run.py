"""``conveyor-twin run``: the twin on a cell for a bounded time, with progress and a summary.

Composed (default): the micro, macro and coordinator nodes in this process, stepped in memory.
``--split``: the three nodes as three processes coupled over ROS topics.

Exit codes: 0 done; 1 invalid cell, or the twin could not start; 2 invalid options;
3 stopped after a failure of a step, a background thread or a node process (reported once with
its traceback, ERROR in the diagnostics, named in the summary).
"""

import argparse
import json
import os
import signal
import sys
import time
from typing import List

from conveyor_twin.cell import CellError, load_cell
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE, Health

DEFAULT_DURATION = 10.0  # s of simulated time
# s between two looks of the main thread at the run (a failure wakes it at once): every wake-up
# takes the interpreter lock, which a step in progress then hands over
MAIN_POLL = 0.1


def ros_environment() -> None:
    """Keep DDS traffic on this machine unless the user chose otherwise."""
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``run``."""
    p = argparse.ArgumentParser(prog='conveyor-twin run', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('--cell', default='', help='cell YAML (default: the embedded default cell)')
    p.add_argument('--seed', type=int, default=None, help="seed (default: the cell's seed)")
    p.add_argument('--mode', default='realtime', choices=[m.value for m in TimeMode])
    p.add_argument('--duration', type=float, default=DEFAULT_DURATION,
                   help='simulated seconds to run (0: until Ctrl-C) [s]')
    p.add_argument('--split', action='store_true',
                   help='run the three nodes as three processes coupled over ROS topics')
    p.add_argument('--namespace', default=None, help='ROS namespace of the nodes')
    p.add_argument('--markers-rate', type=float, default=30.0,
                   help='MarkerArray rate on `markers` [Hz]; 0 disables')
    p.add_argument('--foxglove', default=None, metavar='[HOST:]PORT',
                   help='serve a live Foxglove view (WebSocket) at HOST:PORT; host 127.0.0.1 '
                   'by default, port 0 picks a free one')
    p.add_argument('--foxglove-rate', type=float, default=50.0,
                   help='rate of the every-step streams sent to Foxglove clients [Hz] '
                   '(composed layout; split: 50)')
    p.add_argument('--scenario', default='', metavar='FILE',
                   help='fault scenario YAML: faults by step or time, or triggered by the '
                   "cell's state (docs/faults.md); checked before the twin starts")
    add_plc_arguments(p)
    p.add_argument('--json', action='store_true', help='print the summary as one JSON object')
    p.add_argument('--quiet', action='store_true', help='no progress line')
    from conveyor_twin.cli.record import add_recording_arguments
    add_recording_arguments(p)
    return p


def add_plc_arguments(p: argparse.ArgumentParser, *, plant: bool = False) -> None:
    """Add the PLC servers' options (docs/plc.md); ``plant``: the ports are base ports (cell
    i of the plant serves at BASE + i)."""
    each = ('; cell i of the plant serves at PORT + i (port 0: each cell a free one)'
            if plant else '')
    p.add_argument('--opcua', default=None, metavar='[HOST:]PORT',
                   help='serve OPC UA at HOST:PORT (host 127.0.0.1 by default, port 0 picks a '
                   f'free one; the standard port is 4840){each}')
    p.add_argument('--modbus', default=None, metavar='[HOST:]PORT',
                   help='serve Modbus TCP at HOST:PORT (host 127.0.0.1 by default, port 0 '
                   f'picks a free one; the standard port is 502){each}')
    p.add_argument('--plc-read-only', action='store_true',
                   help='the PLC servers refuse every write (setpoints, targets, stepping)')
    p.add_argument('--opcua-security', default='Basic256Sha256',
                   choices=['Basic256Sha256', 'None'],
                   help='OPC UA security policy (default Basic256Sha256, sign and encrypt)')
    p.add_argument('--opcua-user', default='', metavar='USER',
                   help='OPC UA user name (password from the environment variable '
                   'CONVEYOR_TWIN_OPCUA_PASSWORD); default: anonymous')
    p.add_argument('--opcua-cert-dir', default='', metavar='DIR',
                   help="folder of the OPC UA server's certificate and key (made on first "
                   'start; default ~/.local/share/conveyor_twin/opcua)')


def plc_options(args: argparse.Namespace):
    """Return the :class:`~conveyor_twin.plc.options.PlcOptions` of the command line (None
    without ``--opcua``/``--modbus``).

    :raises ValueError: on an invalid address or combination (the message names it).
    """
    if args.opcua is None and args.modbus is None:
        return None
    from conveyor_twin.plc.address import parse_address
    from conveyor_twin.plc.options import options_from_env
    for flag, address in (('--opcua', args.opcua), ('--modbus', args.modbus)):
        if address is not None:
            parse_address(address, option=flag)
    return options_from_env(args.opcua, args.modbus, read_only=args.plc_read_only,
                            security=args.opcua_security, user=args.opcua_user,
                            cert_dir=args.opcua_cert_dir)


def _progress(summary: dict, wall: float) -> str:
    total_in = summary.get('micro_entered', 0) + summary.get('macro_entered', 0.0)
    return (f"[{wall:6.1f} s] sim {summary['sim_time_s']:7.3f} s  step {summary['steps']:>7}  "
            f"parts micro {summary.get('micro_in_flight', 0):>5} "
            f"macro {summary.get('macro_in_flight', 0.0):8.2f}  entered {total_in:>6g}  "
            f"left {summary.get('micro_left', 0) + summary.get('macro_left', 0.0):>6g}  "
            f"step mean {summary['step_time_ms']['mean']:.3f} ms "
            f"p99 {summary['step_time_ms']['p99']:.3f} ms  "
            f"overruns {summary['overruns']}  rtf {summary['real_time_factor']:.3f}")


def _print_summary(summary: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(summary, sort_keys=True))
        return
    for failure in summary.get('failures', ()):
        print(f"conveyor_twin: FAILED: {failure['name']}: {failure['error']}")
    st = summary['step_time_ms']
    print(f"conveyor_twin: cell {summary['cell']!r}, seed {summary['seed']}, "
          f"{summary['mode']} mode, {summary['steps']} steps ({summary['sim_time_s']:.3f} s "
          f'simulated)')
    print(f"  parts  micro: entered {summary.get('micro_entered', 0)}, left "
          f"{summary.get('micro_left', 0)}, in flight {summary.get('micro_in_flight', 0)}; "
          f"macro: entered {summary.get('macro_entered', 0.0):g}, left "
          f"{summary.get('macro_left', 0.0):g}, in flight "
          f"{summary.get('macro_in_flight', 0.0):g}")
    print(f"  step time mean {st['mean']:.4f} ms, p50 {st['p50']:.4f} ms, p99 {st['p99']:.4f} "
          f"ms, max {st['max']:.4f} ms; overruns {summary['overruns']}; real-time factor "
          f"{summary['real_time_factor']:.3f}; rejected commands "
          f"{summary['rejected_commands']}")


def run_composed(args: argparse.Namespace) -> int:
    """Run the composed layout in this process; return the exit code."""
    import rclpy
    from rclpy.context import Context

    from conveyor_twin.coord.runner import raise_thread_priority, realtime_priority
    from conveyor_twin.ros.compose import ComposedTwin

    try:
        cell = load_cell(args.cell)
    except CellError as exc:
        print(f'invalid cell: {exc}', file=sys.stderr)
        return 1
    seed = cell.settings.seed if args.seed is None else args.seed
    scenario = None
    if args.scenario:
        from conveyor_twin.faults.scenario import load_scenario, ScenarioError
        try:
            scenario = load_scenario(args.scenario, cell)
        except ScenarioError as exc:
            print(f'invalid scenario: {exc}; the twin was not started', file=sys.stderr)
            return 2
    mode = TimeMode(args.mode)
    max_steps = round(args.duration / cell.settings.step) if args.duration > 0 else None
    context = Context()
    rclpy.init(context=context, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    from conveyor_twin.plc.address import PlcServerError
    from conveyor_twin.viz.foxglove_view import FoxgloveError
    try:
        twin = ComposedTwin(cell, seed=seed, mode=mode, context=context,
                            namespace=args.namespace, markers_rate=args.markers_rate,
                            max_steps=max_steps, foxglove=args.foxglove or '',
                            foxglove_rate=args.foxglove_rate, scenario=scenario,
                            plc=plc_options(args))
    except (FoxgloveError, PlcServerError) as exc:
        print(f'conveyor-twin run: {exc}; the twin was not started', file=sys.stderr)
        context.try_shutdown()
        return 2
    if twin.plc is not None:
        for line in twin.plc.describe():
            print(f'conveyor_twin: {line}', file=sys.stderr if args.json else sys.stdout,
                  flush=True)
    from conveyor_twin.record.errors import RecordingError
    from conveyor_twin.cli.record import recording_options
    from conveyor_twin.ros.run_recording import format_recording, start_recording
    try:
        recording = start_recording(twin, recording_options(args), seed=seed,
                                    mode=mode.value)
    except (ValueError, RecordingError) as exc:
        print(f'conveyor-twin run: {exc}', file=sys.stderr)
        twin.stop()
        context.try_shutdown()
        return 2
    interrupted = []
    signal.signal(signal.SIGINT, lambda *_: interrupted.append(True))
    signal.signal(signal.SIGTERM, lambda *_: interrupted.append(True))
    start = time.monotonic()
    health = twin.health
    twin.start()
    if mode is TimeMode.REALTIME:  # this thread takes the GIL the stepping thread needs
        raise_thread_priority(realtime_priority(helper=True))
    tty = sys.stderr.isatty()
    try:
        next_progress = start + 1.0
        while not interrupted and not health.failed:
            if mode is not TimeMode.LOCKSTEP and not twin.runner.running:
                break
            if max_steps is not None and twin.twin.step_index >= max_steps:
                break
            health.event.wait(MAIN_POLL)
            if not args.quiet and time.monotonic() >= next_progress:
                next_progress += 1.0
                line = _progress(twin.coordinator.summary(), time.monotonic() - start)
                print(('\r' + line) if tty else line, end='' if tty else '\n',
                      file=sys.stderr, flush=True)
    finally:
        twin.stop()  # after a failure: publishes (and records) the ERROR diagnostics first
        summary = twin.coordinator.summary()
        if recording is not None:
            try:
                summary['recording'] = recording.close()
            except RecordingError as exc:  # the writer failed: reported to the health
                summary['recording'] = {'error': str(exc)}
        context.try_shutdown()
    if health.failed:
        summary['failures'] = health.summary()
    if not args.quiet and tty:
        print(file=sys.stderr)
    _print_summary(summary, args.json)
    if recording is not None and not args.json:
        print(format_recording(summary['recording']) if 'error' not in summary['recording']
              else f"  recording failed: {summary['recording']['error']}")
    return _failure_exit(summary)


def _failure_exit(summary: dict) -> int:
    """Return 0, or :data:`EXIT_BACKGROUND_FAILURE` naming the failures on stderr."""
    failures = summary.get('failures')
    if not failures:
        return 0
    names = '; '.join(f"{f['name']}: {f['error']}" for f in failures)
    print(f'conveyor-twin run: stopped after a failure ({names}); exit code '
          f'{EXIT_BACKGROUND_FAILURE}', file=sys.stderr, flush=True)
    return EXIT_BACKGROUND_FAILURE


def run_split(args: argparse.Namespace) -> int:
    """Start the three node processes, wait for the coordinator, print its summary."""
    from conveyor_twin.split.launch import launch, ros_args, SUMMARY_PREFIX

    cell_file = os.path.abspath(args.cell) if args.cell else ''
    try:
        cell = load_cell(cell_file or None)
    except CellError as exc:
        print(f'invalid cell: {exc}', file=sys.stderr)
        return 1
    scenario_file = os.path.abspath(args.scenario) if args.scenario else ''
    if scenario_file:
        from conveyor_twin.faults.scenario import load_scenario, ScenarioError
        try:
            load_scenario(scenario_file, cell)
        except ScenarioError as exc:
            print(f'invalid scenario: {exc}; the twin was not started', file=sys.stderr)
            return 2
    process_args = ros_args(cell_file, args.seed, args.mode, args.duration, args.namespace,
                            args.markers_rate, foxglove=args.foxglove or '',
                            scenario=scenario_file)
    health = Health()  # this process's view of the three node processes
    # the scale processes ignore SIGINT: stopped by SIGTERM, after the coordinator
    processes = launch(process_args, ignore_sigint=True)
    coordinator = processes.coordinator
    processes.watch(health)
    summary = None

    def read_until_eof() -> None:
        nonlocal summary
        for line in coordinator.proc.stdout:
            if line.startswith(SUMMARY_PREFIX):
                summary = json.loads(line[len(SUMMARY_PREFIX):])
            elif not args.quiet:
                print(line, end='', file=sys.stderr)

    try:
        try:
            read_until_eof()
        except KeyboardInterrupt:
            # the coordinator stops on SIGINT and prints its summary: keep reading it
            coordinator.proc.send_signal(signal.SIGINT)
            read_until_eof()
        code = coordinator.proc.wait(30)
    finally:
        processes.end_watch()
        processes.stop_scales()
    for child in processes.scales:  # a thread of it failed while it stopped
        if child.proc.returncode == EXIT_BACKGROUND_FAILURE:
            child.report(health, 'after a failure of one of its threads')
    if summary is None:
        coordinator.report(health, 'without a summary')
        print('the coordinator process ended without a summary', file=sys.stderr)
        return EXIT_BACKGROUND_FAILURE
    summary['layout'] = 'split'
    if health.failed:  # the processes seen here (with exit codes), then the coordinator's
        seen = health.summary()
        known = {f['name'] for f in seen}
        summary['failures'] = seen + [f for f in summary.get('failures', ())
                                      if f['name'] not in known]
    _print_summary(summary, args.json)
    if summary.get('failures'):
        return _failure_exit(summary)
    return code


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin run``."""
    args = build_parser().parse_args(argv)
    ros_environment()
    if args.split and (args.record or args.command):
        print('conveyor-twin run: --record and --command need the composed layout (no --split)',
              file=sys.stderr)
        return 2
    if args.foxglove is not None:
        from conveyor_twin.viz.foxglove_view import FoxgloveError, parse_address
        try:
            parse_address(args.foxglove)
        except FoxgloveError as exc:
            print(f'conveyor-twin run: {exc}', file=sys.stderr)
            return 2
    try:
        plc = plc_options(args)
    except ValueError as exc:
        print(f'conveyor-twin run: {exc}', file=sys.stderr)
        return 2
    if plc is not None and args.split:
        print('conveyor-twin run: --opcua and --modbus need the composed layout (no --split): '
              'the split layout makes the light-barrier edges in the micro process and takes '
              'commands in the coordinator process', file=sys.stderr)
        return 2
    if args.split:
        return run_split(args)
    return run_composed(args)
