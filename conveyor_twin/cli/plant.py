"""``conveyor-twin plant PLANT.yaml``: run a plant of cells, print progress and the ledger.

``--processes`` (default): one process per cell (``conveyor-twin plant PLANT.yaml --cell NAME``
each), coupled over ROS 2 topics, supervised: a cell process that dies is reported (exit status,
last output, the plant's diagnostics) and the others run on; ``--restart-dead N`` starts a dead
cell again, up to N times. The same command with ``--cell`` runs one cell, e.g. on another host
(docs/plant.md). ``--composed``: every cell in this process.

Progress lines go to standard error, the summary to standard output (``--json``: one JSON
object and nothing else). Exit status: 0 the run completed (or was interrupted, without an end),
1 it did not complete, 2 a bad plant file or option (before anything starts), 3 a cell process
or a background thread died (even if restarted).
"""

import argparse
import json
import os
import signal
import sys
import time
from typing import Dict, List, Optional, Sequence, Tuple

from conveyor_twin.cell.errors import CellError
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE, Health
from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.model import Plant

DEFAULT_DURATION = 10.0  # s of simulated time
#: Longest wait for the cells after the end step, and for a cell to stop [s].
FINISH_TIMEOUT = 60.0
#: With a cell dead for good, a run of fixed duration ends once no other cell has stepped for
#: this long (the cells that depend on the dead one wait for it forever) [s of wall time].
STALLED_AFTER = 10.0
#: A cell whose node has been out of the ROS graph this long, not done, is said to be gone [s].
GONE_AFTER = 3.0
#: A done cell that has waited this long for its neighbours' done reports says which [s].
WAITING_SAID_AFTER = 10.0


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``plant``."""
    p = argparse.ArgumentParser(prog='conveyor-twin plant', description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument('plant', help='plant YAML (docs/plant.md)')
    layout = p.add_mutually_exclusive_group()
    layout.add_argument('--processes', action='store_true',
                        help='one process per cell (the default)')
    layout.add_argument('--composed', action='store_true', help='every cell in this process')
    layout.add_argument('--cell', default='', help='run only this cell (as each process of '
                        '--processes does; start one per cell, on any host)')
    layout.add_argument('--monitor', action='store_true',
                        help='start no cell: show the progress and ledger of cells started '
                        'with --cell (on any host) and publish the plant\'s diagnostics')
    p.add_argument('--mode', default='fast', choices=[m.value for m in TimeMode])
    p.add_argument('--duration', type=float, default=DEFAULT_DURATION,
                   help='simulated seconds to run (0: until Ctrl-C) [s]')
    p.add_argument('--run-id', type=int, default=None,
                   help='id of this run of the cell (--cell; default: from the clock, so a '
                   'restarted cell gets the parts its links hold sent again)')
    p.add_argument('--hold', action='store_true',
                   help='--cell: after the end, keep reporting until a signal (the parent of '
                   '--processes stops its cells itself)')
    p.add_argument('--no-streams', action='store_true',
                   help="serve only the links, not each cell's own topics and services")
    p.add_argument('--record', default='', metavar='DIR',
                   help="record each cell's streams to DIR/<cell>.mcap (replay them with "
                   '`conveyor-twin replay`)')
    p.add_argument('--restart-dead', type=int, default=0, metavar='N',
                   help='--processes: start a cell process that died again, at most N times '
                   'per cell (default 0: report it, keep the other cells running)')
    p.add_argument('--json', action='store_true',
                   help='print the summary as one JSON object (the only output on stdout)')
    p.add_argument('--quiet', action='store_true', help='no progress lines (on stderr)')
    p.add_argument('--foxglove', default='', metavar='[HOST:]PORT',
                   help='serve one live Foxglove view of every cell (docs/foxglove.md)')
    p.add_argument('--discovery-server', default='', metavar='[start:][HOST:]PORT',
                   help='discover the other processes only through the Fast DDS discovery '
                   'server at [HOST:]PORT (HOST default 127.0.0.1), for cells on hosts '
                   'without multicast; start[:[HOST:]PORT]: start one listening there '
                   '(default 127.0.0.1:11811) for the run, and use it (not with --cell)')
    from conveyor_twin.cli.run import add_plc_arguments
    add_plc_arguments(p, plant=True)
    return p


def _cell_plc(plant: Plant, args: argparse.Namespace, name: str):
    """Return the PLC options of cell ``name`` (its ports: the base ports + its index in the
    plant), or None without ``--opcua``/``--modbus``."""
    from conveyor_twin.cli.run import plc_options
    options = plc_options(args)
    if options is None:
        return None
    return options.for_cell([c.name for c in plant.cells].index(name))


def _init_ros():
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    import rclpy
    from rclpy.context import Context
    context = Context()
    rclpy.init(context=context, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    return context


def _interrupts() -> List[bool]:
    flag: List[bool] = []
    signal.signal(signal.SIGINT, lambda *_: flag.append(True))
    signal.signal(signal.SIGTERM, lambda *_: flag.append(True))
    return flag


def run_cell(plant: Plant, args: argparse.Namespace) -> int:
    """Run one cell until the plant's end step (it and every neighbour done) or a signal."""
    from conveyor_twin.ros.plant_cell_node import PlantCellNode
    end = int(round(args.duration / plant.step)) if args.duration > 0 else 0
    run = args.run_id if args.run_id is not None else time.time_ns() & 0xFFFFFFFFFFFF
    context = _init_ros()
    stop = _interrupts()
    from conveyor_twin.plc.address import PlcServerError
    try:
        node = PlantCellNode(plant, args.cell, context=context, mode=TimeMode(args.mode),
                             end_step=end, run=run, streams=not args.no_streams,
                             record=args.record, plc=_cell_plc(plant, args, args.cell))
    except PlcServerError as exc:
        print(f'conveyor-twin plant: cell {args.cell!r}: {exc}', file=sys.stderr, flush=True)
        context.try_shutdown()
        return 2
    if node.composed is not None and node.composed.plc is not None:
        for line in node.composed.plc.describe():
            print(f'conveyor-twin plant: cell {args.cell!r}: {line}', file=sys.stderr,
                  flush=True)
    node.start()
    try:
        last = 0.0
        done_at = None
        said = False
        while not stop:
            if node.error is not None:
                break
            if node.done.is_set():
                # its neighbours have its final batches once they are done; no other cell
                # needs anything from it (a monitor gets the done report before it ends)
                if not node.neighbours_not_done() and not args.hold:
                    break
                now = time.monotonic()
                done_at = now if done_at is None else done_at
                if now - last > 0.5:  # a late subscriber gets it too
                    node.report_done()
                    last = now
                if not said and not args.hold and now - done_at > WAITING_SAID_AFTER:
                    print(f'conveyor-twin plant: {node.describe_waiting()}', file=sys.stderr,
                          flush=True)
                    said = True
            time.sleep(0.05)
    finally:
        if node.done.is_set() and node.neighbours_not_done() and not args.hold:
            print(f'conveyor-twin plant: stopped: {node.describe_waiting()}', file=sys.stderr,
                  flush=True)
        node.stop()
        core = node.core
        print(json.dumps({'cell': core.name, 'step': core.step_index,
                          'state_hash': core.state_hash(), 'counts': core.counts(),
                          'real_time_factor': node.real_time_factor()}, sort_keys=True),
              flush=True)
        context.try_shutdown()
    if node.error is not None or not node.health.ok:
        print(f'conveyor-twin plant: cell {args.cell!r} failed: '
              + '; '.join(f.describe() for f in node.health.failures), file=sys.stderr)
        return EXIT_BACKGROUND_FAILURE
    return 0


def _progress_line(wall: float, monitor, step: float, dead: Sequence[str] = ()) -> str:
    """One progress line: the plant's time (every cell's simulated time over all its runs, the
    least of them), every cell's step in its current run, and the ledger."""
    simulated = monitor.simulated_steps()
    restarts = monitor.restarts()
    lowest = min(simulated.values()) if simulated else 0
    cells = []
    for name, v in monitor.steps().items():
        mark = ' dead' if name in dead else ''
        run = f' run {restarts[name] + 1}' if restarts.get(name) else ''
        cells.append(f'{name}:{v}' + (f'({(run + mark).strip()})' if run or mark else ''))
    ledger = monitor.ledger()
    return (f'[{wall:6.1f} s] plant at {max(lowest, 0) * step:7.3f} s  steps {" ".join(cells)}'
            f'  entered {ledger.entered:g} in cells {ledger.in_cells:g} in links '
            f'{ledger.in_links} left {ledger.left:g}')


def _cell_command(args: argparse.Namespace, name: str) -> List[str]:
    cmd = [sys.executable, '-m', 'conveyor_twin.cli', 'plant', args.plant, '--cell', name,
           '--mode', args.mode, '--duration', repr(args.duration), '--quiet', '--hold']
    if args.no_streams:
        cmd.append('--no-streams')
    if args.record:
        cmd += ['--record', args.record]
    if getattr(args, 'discovery', None) is not None:
        cmd += ['--discovery-server', args.discovery.describe()]
    for flag, value in (('--opcua', args.opcua), ('--modbus', args.modbus),
                        ('--opcua-security', args.opcua_security),
                        ('--opcua-user', args.opcua_user),
                        ('--opcua-cert-dir', args.opcua_cert_dir)):
        if value:
            cmd += [flag, value]
    if args.plc_read_only:
        cmd.append('--plc-read-only')
    return cmd


def run_plant(plant: Plant, args: argparse.Namespace) -> int:
    """Run the whole plant (processes or composed), print progress and the summary."""
    from conveyor_twin.plant.supervisor import CellProcesses
    from conveyor_twin.ros.plant_monitor import PlantMonitor
    from conveyor_twin.ros.plant_node import ComposedPlant
    end = int(round(args.duration / plant.step)) if args.duration > 0 else 0
    context = _init_ros()
    stop = _interrupts()
    health = Health()
    monitor = PlantMonitor(plant, context=context, health=health)
    from conveyor_twin.ros.compat import make_executor
    executor = make_executor(context)
    executor.add_node(monitor.node)
    view = _start_foxglove(plant, args, monitor.node, health)  # None without --foxglove
    composed: Optional[ComposedPlant] = None
    cells: Optional[CellProcesses] = None
    t0 = time.monotonic()
    finals: List[dict] = []
    server = None
    try:
        server = _start_discovery_server(args, health)  # None without --discovery-server start
        if args.monitor:
            pass
        elif args.composed:
            composed = ComposedPlant(plant, context=context, mode=TimeMode(args.mode),
                                     end_step=end, streams=not args.no_streams,
                                     record=args.record)
            composed.start()
        else:
            cells = CellProcesses({c.name: _cell_command(args, c.name) for c in plant.cells},
                                  health=health, restarts=args.restart_dead)
            cells.start()
        last = 0.0
        gone: Dict[Tuple[str, int], float] = {}
        moved_at, seen = time.monotonic(), monitor.simulated_steps()
        while not stop:
            executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            if now - last >= 1.0:
                last = now
                monitor.publish_diagnostics()
                if args.monitor:
                    _warn_gone(monitor, gone, now)
                if not args.quiet:
                    print(_progress_line(now - t0, monitor, plant.step,
                                         cells.dead if cells else ()),
                          file=sys.stderr, flush=True)
            if end and monitor.all_done():
                break
            if composed is not None and (composed.error is not None or composed.failures()):
                break
            if cells is None:
                continue
            cells.watch(lambda name: name in monitor.reports and monitor.reports[name].done)
            steps = monitor.simulated_steps()
            if steps != seen:
                moved_at, seen = now, steps
            live = [c.name for c in plant.cells if c.name not in cells.dead]
            if end and cells.dead and (
                    all(n in monitor.reports and monitor.reports[n].done for n in live)
                    or now - moved_at >= STALLED_AFTER):
                print(f'conveyor-twin plant: ending the run: cell(s) {cells.dead} dead, the '
                      'others done or waiting for them', file=sys.stderr, flush=True)
                break
        for _ in range(10):  # the last reports
            executor.spin_once(timeout_sec=0.02)
        monitor.publish_diagnostics()
    finally:
        if view is not None:
            view.stop()
        if composed is not None:
            composed.stop()
        if cells is not None:
            finals = cells.stop(FINISH_TIMEOUT)
        if server is not None:
            server.stop()
        executor.shutdown(timeout_sec=2.0)
        monitor.destroy()
        context.try_shutdown()
    ledger = monitor.ledger()
    wall = time.monotonic() - t0
    steps = monitor.steps()
    simulated = monitor.simulated_steps()
    failures = [f.describe() for f in health.failures]
    if composed is not None:
        failures += composed.failures()
    layout = 'composed' if args.composed else 'monitor' if args.monitor else 'processes'
    summary = {'plant': plant.name, 'layout': layout,
               'mode': args.mode, 'cells': len(plant.cells), 'steps': steps,
               'simulated_steps': simulated,
               'sim_time_s': max(min(steps.values()), 0) * plant.step, 'wall_s': wall,
               'ledger': ledger.as_dict(),
               'state_hashes': {m.cell: m.state_hash for m in monitor.reports.values()},
               'cells_rtf': {m.cell: m.real_time_factor for m in monitor.reports.values()},
               'restarts': cells.restarts() if cells else {}, 'dead': cells.dead if cells
               else [], 'failures': failures, 'cell_summaries': len(finals)}
    summary['real_time_factor'] = summary['sim_time_s'] / wall if wall > 0 else 0.0
    if args.json:
        print(json.dumps(summary, sort_keys=True), flush=True)
    else:
        print(f"conveyor_twin plant {plant.name!r}: {len(plant.cells)} cells "
              f"({summary['layout']}), {args.mode} mode, {summary['sim_time_s']:.3f} s "
              f"simulated in {wall:.1f} s (real-time factor {summary['real_time_factor']:.2f})")
        print(ledger.text())
    if failures:
        print('conveyor-twin plant: failed: ' + '; '.join(failures), file=sys.stderr)
        return EXIT_BACKGROUND_FAILURE
    complete = bool(end) and monitor.all_done()
    return 0 if complete or (not end and stop) else 1


def _warn_gone(monitor, gone: Dict[Tuple[str, int], float], now: float) -> None:
    """Say once per cell run that its process left before its ``done`` report arrived (gone
    for :data:`GONE_AFTER` s); ``gone`` maps (cell, run) to when it was first missed (a
    negative time: said)."""
    for name in monitor.gone_unfinished():
        report = monitor.reports[name]
        since = gone.setdefault((name, report.run), now)
        if 0.0 <= since <= now - GONE_AFTER:
            gone[(name, report.run)] = -1.0
            print(f'conveyor-twin plant: cell {name!r} (run {report.run}) left at step '
                  f'{report.step} before its done report arrived; waiting for it to run again',
                  file=sys.stderr, flush=True)


def _start_discovery_server(args: argparse.Namespace, health: Health):
    """Start the discovery server of ``--discovery-server start...`` (its end before the run's
    is reported to ``health``); None without it."""
    setting = getattr(args, 'discovery', None)
    if setting is None or not setting.start:
        return None
    from conveyor_twin.plant.discovery import DiscoveryError, DiscoveryServer
    server = DiscoveryServer(setting.address, health=health)
    try:
        server.start()
    except DiscoveryError as exc:  # before any cell starts
        print(f'conveyor-twin plant: {exc}', file=sys.stderr, flush=True)
        raise SystemExit(2) from None
    print(f'conveyor-twin plant: discovery server at {setting.address} (pid {server.pid})',
          file=sys.stderr, flush=True)
    return server


def _start_foxglove(plant: Plant, args: argparse.Namespace, node, health: Health):
    """Start the plant's Foxglove view (``--foxglove``) on ``node``; None without it."""
    if not args.foxglove:
        return None
    from conveyor_twin.ros.foxglove_bridge import attach_plant
    from conveyor_twin.viz.foxglove_view import FoxgloveError
    try:
        view = attach_plant(node, plant, args.foxglove, health=health)
    except FoxgloveError as exc:  # before any cell starts
        print(f'conveyor-twin plant: {exc}', file=sys.stderr, flush=True)
        raise SystemExit(2) from None
    host = args.foxglove.rpartition(':')[0] or '127.0.0.1'
    print(f'conveyor-twin plant: Foxglove view at ws://{host}:{view.port}', file=sys.stderr,
          flush=True)
    return view


def main(argv: List[str]) -> int:
    """Entry point of ``conveyor-twin plant``; return the exit code."""
    args = build_parser().parse_args(argv)
    try:
        plant = load_plant(args.plant)
    except CellError as exc:
        print(f'conveyor-twin plant: {exc}', file=sys.stderr)
        return 2
    if args.duration < 0 or args.duration != args.duration:
        print(f'conveyor-twin plant: --duration: got {args.duration}; expected a number of '
              'seconds >= 0 (0: until Ctrl-C)', file=sys.stderr)
        return 2
    if args.run_id is not None and not 0 <= args.run_id < 1 << 64:
        print(f'conveyor-twin plant: --run-id: got {args.run_id}; expected an integer in '
              '[0, 2^64)', file=sys.stderr)
        return 2
    if args.restart_dead < 0:
        print(f'conveyor-twin plant: --restart-dead: got {args.restart_dead}; expected an '
              'integer >= 0 (restarts per cell)', file=sys.stderr)
        return 2
    if args.record and args.no_streams:
        print('conveyor-twin plant: --record needs the cells\' streams (not --no-streams)',
              file=sys.stderr)
        return 2
    if args.foxglove:  # one view of the whole plant, served by the parent or the monitor
        from conveyor_twin.viz.foxglove_view import FoxgloveError, parse_address
        try:
            parse_address(args.foxglove)
        except FoxgloveError as exc:
            print(f'conveyor-twin plant: {exc}', file=sys.stderr)
            return 2
        if args.cell or args.no_streams:
            print("conveyor-twin plant: --foxglove shows every cell's streams: not with --cell "
                  'or --no-streams', file=sys.stderr)
            return 2
    if args.opcua is not None or args.modbus is not None:
        if args.composed or args.monitor or args.no_streams:
            print('conveyor-twin plant: --opcua/--modbus: each cell serves its own, with its '
                  'streams, in its process: not with --composed, --monitor or --no-streams',
                  file=sys.stderr)
            return 2
        try:
            for index in range(len(plant.cells)):
                _cell_plc(plant, args, plant.cells[index].name)
        except ValueError as exc:
            print(f'conveyor-twin plant: {exc}', file=sys.stderr)
            return 2
    args.discovery = None
    if args.discovery_server:  # before anything creates a ROS context: Fast DDS reads it then
        from conveyor_twin.plant.discovery import (client_environment, DiscoveryError,
                                                   parse_discovery_server)
        try:
            args.discovery = parse_discovery_server(args.discovery_server)
        except DiscoveryError as exc:
            print(f'conveyor-twin plant: {exc}', file=sys.stderr)
            return 2
        if args.discovery.start and args.cell:
            print('conveyor-twin plant: --discovery-server start: a cell process uses a server '
                  '([HOST:]PORT); start one with the plant (--processes, --composed or '
                  '--monitor)', file=sys.stderr)
            return 2
        os.environ.update(client_environment(args.discovery.address))
    if args.cell:
        if args.cell not in [c.name for c in plant.cells]:
            print(f'conveyor-twin plant: {args.plant}: no cell {args.cell!r} (cells: '
                  + ', '.join(c.name for c in plant.cells) + ')', file=sys.stderr)
            return 2
        return run_cell(plant, args)
    return run_plant(plant, args)
