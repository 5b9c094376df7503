"""``conveyor-twin plant PLANT.yaml``: run a plant of cells, print progress and the ledger.

``--processes`` (default): one process per cell (``conveyor-twin plant PLANT.yaml --cell NAME``
each), coupled over ROS 2 topics; the same command with ``--cell`` runs one cell, e.g. on
another host (docs/plant.md). ``--composed``: every cell in this process. A bad plant or cell
file exits with status 2 before anything starts.
"""

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from typing import Dict, List, Optional

from conveyor_twin.cell.errors import CellError
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.model import Plant

DEFAULT_DURATION = 10.0  # s of simulated time
#: Longest wait for the cells after the end step, and for a cell to stop [s].
FINISH_TIMEOUT = 60.0


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
    p.add_argument('--json', action='store_true', help='print the summary as one JSON object')
    p.add_argument('--quiet', action='store_true', help='no progress lines')
    return p


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
    """Run one cell until the plant's end step (every cell done) or a signal."""
    from conveyor_twin.ros.plant_node import PlantCellNode
    end = int(round(args.duration / plant.step)) if args.duration > 0 else 0
    run = args.run_id if args.run_id is not None else time.time_ns() & 0xFFFFFFFFFFFF
    context = _init_ros()
    stop = _interrupts()
    node = PlantCellNode(plant, args.cell, context=context, mode=TimeMode(args.mode),
                         end_step=end, run=run, streams=not args.no_streams,
                         record=args.record)
    node.start()
    try:
        last = 0.0
        while not stop:
            if node.error is not None:
                break
            if node.done.is_set():
                if node.all_done() and not args.hold:
                    break
                if time.monotonic() - last > 0.5:  # a late subscriber gets it too
                    node.report_done()
                    last = time.monotonic()
            time.sleep(0.05)
    finally:
        node.stop()
        core = node.core
        print(json.dumps({'cell': core.name, 'step': core.step_index,
                          'state_hash': core.state_hash(), 'counts': core.counts(),
                          'real_time_factor': node.real_time_factor()}, sort_keys=True),
              flush=True)
        context.try_shutdown()
    return 1 if node.error is not None else 0


def _progress_line(wall: float, steps: Dict[str, int], ledger, step: float) -> str:
    lowest = min(steps.values()) if steps else 0
    cells = ' '.join(f'{k}:{v}' for k, v in steps.items())
    return (f'[{wall:6.1f} s] plant at {max(lowest, 0) * step:7.3f} s  steps {cells}  '
            f'entered {ledger.entered:g} in cells {ledger.in_cells:g} in links '
            f'{ledger.in_links} left {ledger.left:g}')


def run_plant(plant: Plant, args: argparse.Namespace) -> int:
    """Run the whole plant (processes or composed), print progress and the summary."""
    from conveyor_twin.ros.plant_node import ComposedPlant, PlantMonitor
    end = int(round(args.duration / plant.step)) if args.duration > 0 else 0
    context = _init_ros()
    stop = _interrupts()
    monitor = PlantMonitor(plant, context=context)
    from conveyor_twin.ros.compat import make_executor
    executor = make_executor(context)
    executor.add_node(monitor.node)
    composed: Optional[ComposedPlant] = None
    procs: List[subprocess.Popen] = []
    t0 = time.monotonic()
    try:
        if args.monitor:
            pass
        elif args.composed:
            composed = ComposedPlant(plant, context=context, mode=TimeMode(args.mode),
                                     end_step=end, streams=not args.no_streams,
                                     record=args.record)
            composed.start()
        else:
            for c in plant.cells:
                cmd = [sys.executable, '-m', 'conveyor_twin.cli', 'plant', args.plant,
                       '--cell', c.name, '--mode', args.mode, '--duration',
                       repr(args.duration), '--quiet', '--hold']
                if args.no_streams:
                    cmd.append('--no-streams')
                if args.record:
                    cmd += ['--record', args.record]
                procs.append(subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True,
                                              start_new_session=True))
        last = 0.0
        while not stop:
            executor.spin_once(timeout_sec=0.05)
            now = time.monotonic()
            if now - last >= 1.0:
                last = now
                monitor.publish_diagnostics()
                if not args.quiet:
                    print(_progress_line(now - t0, monitor.steps(), monitor.ledger(),
                                         plant.step), flush=True)
            if end and monitor.all_done():
                break
            if composed is not None and composed.error is not None:
                break
            early = [c.name for c, p in zip(plant.cells, procs) if p.poll() is not None
                     and (p.returncode != 0 or c.name not in monitor.reports
                          or not monitor.reports[c.name].done)]
            if early:
                codes = {c.name: p.poll() for c, p in zip(plant.cells, procs)}
                print(f'conveyor-twin plant: cell process(es) {early} ended early (exit codes '
                      f'{codes})', file=sys.stderr)
                break
        for _ in range(10):  # the last reports
            executor.spin_once(timeout_sec=0.02)
        monitor.publish_diagnostics()
    finally:
        if composed is not None:
            composed.stop()
        finals = []
        for p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
        for p in procs:
            try:
                out, _ = p.communicate(timeout=FINISH_TIMEOUT)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                out, _ = p.communicate()
            lines = [x for x in (out or '').splitlines() if x.startswith('{')]
            if lines:
                finals.append(json.loads(lines[-1]))
        executor.shutdown(timeout_sec=2.0)
        monitor.destroy()
        context.try_shutdown()
    ledger = monitor.ledger()
    wall = time.monotonic() - t0
    steps = monitor.steps()
    layout = 'composed' if args.composed else 'monitor' if args.monitor else 'processes'
    summary = {'plant': plant.name, 'layout': layout,
               'mode': args.mode, 'cells': len(plant.cells), 'steps': steps,
               'sim_time_s': max(min(steps.values()), 0) * plant.step, 'wall_s': wall,
               'ledger': ledger.as_dict(),
               'state_hashes': {m.cell: m.state_hash for m in monitor.reports.values()},
               'cells_rtf': {m.cell: m.real_time_factor for m in monitor.reports.values()}}
    summary['real_time_factor'] = summary['sim_time_s'] / wall if wall > 0 else 0.0
    if args.json:
        print(json.dumps(summary, sort_keys=True))
    else:
        print(f"conveyor_twin plant {plant.name!r}: {len(plant.cells)} cells "
              f"({summary['layout']}), {args.mode} mode, {summary['sim_time_s']:.3f} s "
              f"simulated in {wall:.1f} s (real-time factor {summary['real_time_factor']:.2f})")
        print(ledger.text())
    complete = bool(end) and monitor.all_done()
    return 0 if complete or (not end and stop) else 1


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
    if args.record and args.no_streams:
        print('conveyor-twin plant: --record needs the cells\' streams (not --no-streams)',
              file=sys.stderr)
        return 2
    if args.cell:
        if args.cell not in [c.name for c in plant.cells]:
            print(f'conveyor-twin plant: {args.plant}: no cell {args.cell!r} (cells: '
                  + ', '.join(c.name for c in plant.cells) + ')', file=sys.stderr)
            return 2
        return run_cell(plant, args)
    return run_plant(plant, args)
