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
import signal
import sys
import threading
from typing import Dict, List, Optional

from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.codec import decode_counters, MACRO_ROLE, MICRO_ROLE
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.ros.coordinator_node import CoordinatorNode
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.standalone import start_process

SCALE_CONNECT_TIMEOUT = 30.0  # s for the scale processes to appear and match
SUMMARY_PREFIX = 'conveyor_twin summary: '


def _remote_counters(node: CoordinatorNode) -> Dict[str, float]:
    replies = node.last_replies()
    return {**decode_counters('micro', replies.get(MICRO_ROLE, b'')),
            **decode_counters('macro', replies.get(MACRO_ROLE, b''))}


def coordinator_main(argv: Optional[List[str]] = None) -> int:
    """Run ``scale_coordinator`` as its own process (split layout); print a summary line."""
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
    holder: Dict[str, CoordinatorNode] = {}
    node = CoordinatorNode(assembled.twin, runner, context=context,
                           remote_roles=assembled.remote_roles,
                           counters=lambda: _remote_counters(holder['node']))
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
    spinners = [threading.Thread(target=spin_until, args=(ex, spin_stop), daemon=True)
                for ex in (executor, coupling_executor)]
    for spinner in spinners:
        spinner.start()
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
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
    if code == 0 and not node.wait_for_scales(SCALE_CONNECT_TIMEOUT):
        node.get_logger().error('micro_simulator and macro_simulator did not connect within '
                                f'{SCALE_CONNECT_TIMEOUT:g} s')
        code = 1
    elif code == 0:
        runner.start()
        while not stop.is_set():
            if params.mode is not TimeMode.LOCKSTEP and not runner.running:
                break
            stop.wait(0.05)
        runner.stop()
        if runner.error is not None:
            node.get_logger().error(f'simulation stopped: {runner.error!r}')
            code = 1
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
