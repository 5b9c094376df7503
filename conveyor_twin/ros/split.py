"""The split layout's coordinator process: micro, macro and coordinator nodes as three processes.

``scale_coordinator`` (this module's :func:`coordinator_main`) drives time; every step it sends
the step input over the coupling topic and waits for both scale nodes to report the step done.
``conveyor-twin run --split`` (:mod:`conveyor_twin.cli.run`) starts the three processes with
:func:`ros_args` and prints the summary line the coordinator prints (:data:`SUMMARY_PREFIX`).
With ``macro``/``auto`` zones the micro and macro nodes also exchange the scale hand-over every
step (micro state to the macro node, edits back; :mod:`conveyor_twin.coord.mirror`), so the
streams are bit-identical to the composed layout's.
"""

import json
import os
import signal
import sys
import threading
import time
from typing import Dict, List, Optional

from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.codec import decode_counters, MACRO_ROLE, MICRO_ROLE
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE, Health, process_alive
from conveyor_twin.ros.coordinator_node import CoordinatorNode, ROLE_NODES
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.standalone import start_process

# s for the scale processes to appear and match: each loads its kernels first (~20 s on a
# loaded 2-core machine); known scale processes that die meanwhile end the wait at once
SCALE_CONNECT_TIMEOUT = 120.0
SUMMARY_PREFIX = 'conveyor_twin summary: '
#: Environment variable through which ``conveyor-twin run --split`` tells the coordinator the
#: process ids of the scale nodes: ``micro_simulator=PID,macro_simulator=PID``.
SCALE_PIDS_ENV = 'CONVEYOR_TWIN_SCALE_PIDS'
WATCH_PERIOD = 0.05  # s between two checks of the run and the scale processes


def scale_pids_from_env(environ=os.environ) -> Dict[int, int]:
    """Return the scale processes' ids by role from :data:`SCALE_PIDS_ENV` (empty if unset)."""
    roles = {name: role for role, name in ROLE_NODES.items()}
    out: Dict[int, int] = {}
    for item in filter(None, environ.get(SCALE_PIDS_ENV, '').split(',')):
        name, _, pid = item.partition('=')
        if name in roles and pid.isdigit():
            out[roles[name]] = int(pid)
    return out


def check_scale_processes(health: Health, pids: Dict[int, int]) -> None:
    """Report every scale process of ``pids`` that has ended to ``health`` (once each)."""
    for role, pid in pids.items():
        if not process_alive(pid):
            health.report(f'{ROLE_NODES[role]} process',
                          message=f'the process (pid {pid}) ended during the run')


def _wait_for_scales(node: CoordinatorNode, health: Health, pids: Dict[int, int],
                     stop: threading.Event) -> bool:
    """Wait up to :data:`SCALE_CONNECT_TIMEOUT` until the scale nodes are connected; return
    True if so. A scale process that ends meanwhile is reported; it, or ``stop``, ends the wait."""
    deadline = time.monotonic() + SCALE_CONNECT_TIMEOUT
    while time.monotonic() < deadline and not stop.is_set():
        if node.wait_for_scales(min(0.25, max(0.0, deadline - time.monotonic()))):
            return True
        check_scale_processes(health, pids)
    return False


def _remote_counters(node: CoordinatorNode) -> Dict[str, float]:
    replies = node.last_replies()
    return {**decode_counters('micro', replies.get(MICRO_ROLE, b'')),
            **decode_counters('macro', replies.get(MACRO_ROLE, b''))}


def coordinator_main(argv: Optional[List[str]] = None) -> int:
    """Run ``scale_coordinator`` as its own process (split layout); print a summary line.

    :return: 0; 1 or 2 if the twin could not start; :data:`EXIT_BACKGROUND_FAILURE` after a
        failure of a step, a thread or a scale process (reported, ERROR in diagnostics).
    """
    started = start_process('scale_coordinator', argv)
    if started is None:
        return 1
    context, params, cell, seed = started
    max_steps = round(params.duration / cell.settings.step) if params.duration > 0 else None
    assembled = build_twin(cell, seed=seed, layout='coordinator')
    scenario = None
    if params.scenario:
        from conveyor_twin.faults.scenario import load_scenario, ScenarioError
        try:
            scenario = load_scenario(params.scenario, cell)
        except ScenarioError as exc:
            print(f'scale_coordinator: scenario refused, the twin was not started: {exc}',
                  file=sys.stderr, flush=True)
            context.try_shutdown()
            return 2
    runner = Runner(assembled.twin, params.mode, max_steps=max_steps)
    health = assembled.twin.health
    pids = scale_pids_from_env()
    holder: Dict[str, CoordinatorNode] = {}
    node = CoordinatorNode(assembled.twin, runner, context=context,
                           remote_roles=assembled.remote_roles,
                           counters=lambda: _remote_counters(holder['node']),
                           scale_pids=pids)
    holder['node'] = node
    if scenario is not None:  # triggers read what the scale nodes measure after each step
        node.measures_wanted = scenario.conditional
        assembled.arm_scenario(scenario, edge_count=node.measured_edge_count,
                               zone_parts_of=node.measured_zone_parts)
    executor = make_executor(context)
    executor.add_node(node)
    coupling_executor = make_executor(context)
    coupling_executor.add_node(node.coupling_node)
    spin_stop = threading.Event()
    spinners = [health.thread(name, spin_until, ex, spin_stop)
                for name, ex in (('executor thread', executor),
                                 ('coupling executor thread', coupling_executor))]
    for spinner in spinners:
        spinner.start()
    stop = threading.Event()
    health.listeners.append(lambda failure: stop.set())

    def on_signal(*_) -> None:
        runner.request_stop()  # at the end of the current step, not 50 ms later
        stop.set()
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    code = 0
    view = None
    if params.foxglove:
        from conveyor_twin.ros.foxglove_bridge import attach_split
        from conveyor_twin.viz.foxglove_view import FoxgloveError
        try:
            view = attach_split(node, params.foxglove)
        except FoxgloveError as exc:
            node.get_logger().error(f'{exc}; the twin was not started')
            code = 2
    if code == 0 and not _wait_for_scales(node, health, pids, stop):
        if not health.failed and not stop.is_set():
            node.get_logger().error('micro_simulator and macro_simulator did not connect '
                                    f'within {SCALE_CONNECT_TIMEOUT:g} s')
            code = 1
    elif code == 0:
        runner.start()
        while not stop.is_set():
            if params.mode is not TimeMode.LOCKSTEP and not runner.running:
                break
            check_scale_processes(health, pids)
            stop.wait(WATCH_PERIOD)
        runner.stop()
    if health.failed:  # every failure (a step too) was reported once and logged at ERROR
        node.publish_diagnostics()
        code = EXIT_BACKGROUND_FAILURE
    print(SUMMARY_PREFIX + json.dumps(node.summary(), sort_keys=True), flush=True)
    if view is not None:
        view.stop()
    spin_stop.set()
    for spinner in spinners:
        spinner.join(5.0)
    executor.shutdown(timeout_sec=5.0)
    coupling_executor.shutdown(timeout_sec=5.0)
    node.coupling_node.destroy_node()
    node.destroy_node()
    context.try_shutdown()
    return code


def ros_args(cell_file: str, seed: Optional[int], mode: str, duration: float,
             namespace: Optional[str], markers_rate: float, *, foxglove: str = '',
             scenario: str = '') -> List[str]:
    """Return the ``--ros-args`` of the three processes of a split run (durations [s], rates
    [Hz]; ``foxglove``: ``[HOST:]PORT`` of the coordinator's Foxglove view, empty: none;
    ``scenario``: the fault scenario file the coordinator arms, empty: none)."""
    args = ['--ros-args', '-p', f'mode:={mode}', '-p', f'duration:={float(duration)}',
            '-p', f'markers_rate:={float(markers_rate)}']
    if cell_file:  # rcl cannot parse an empty override; empty is the default anyway
        args += ['-p', f'cell_file:={cell_file}']
    if seed is not None:
        args += ['-p', f'seed:={seed}']
    if foxglove:  # quoted: rcl would read a bare port as an integer
        args += ['-p', f'foxglove:="{foxglove}"']
    if scenario:
        args += ['-p', f'scenario:={scenario}']
    if namespace:
        args += ['-r', f'__ns:={namespace}']
    return args


if __name__ == '__main__':
    sys.exit(coordinator_main())
