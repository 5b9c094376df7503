"""Run one scale node as its own process (split layout).

A failure of one of the process's threads (its executor, the markers thread) is reported once
with its traceback; the process then ends with :data:`~conveyor_twin.health.EXIT_BACKGROUND_FAILURE`
(the coordinator and ``conveyor-twin run --split`` notice it).
"""

import os
import signal
import sys
import threading
from typing import Callable, List, Optional

import rclpy
from rclpy.context import Context
from rclpy.node import Node

from conveyor_twin.cell import CellError, load_cell
from conveyor_twin.coord.layout import Role
from conveyor_twin.coord.runner import freeze_heap
from conveyor_twin.coord.warmup import warm_up
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE, Health
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.params import declare_twin_parameters
from conveyor_twin.split.launch import IGNORE_SIGINT_ENV
from conveyor_twin.split.roles import build_scale_role, ScaleRole


def start_process(name: str, argv: Optional[List[str]] = None):
    """Initialise rclpy for a node process and read its parameters and cell.

    :param name: node name (the parameters are read by a helper node ``<name>_parameters``).
    :return: (context, parameters, cell, seed), or None after printing why the cell is invalid.
    """
    context = Context()
    rclpy.init(args=argv if argv is not None else sys.argv, context=context,
               signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    bootstrap = rclpy.create_node(name + '_parameters', context=context,
                                  start_parameter_services=False)
    try:
        params = declare_twin_parameters(bootstrap)
    finally:
        bootstrap.destroy_node()
    try:
        cell = load_cell(params.cell_file)
    except CellError as exc:
        print(f'invalid cell: {exc}', file=sys.stderr)
        context.try_shutdown()
        return None
    seed = cell.settings.seed if params.seed < 0 else params.seed
    return context, params, cell, seed


def run_scale_node(role: Role, make_node: Callable[..., Node],
                   argv: Optional[List[str]] = None) -> int:
    """Build the scale ``role`` (micro or macro) of the split layout from the node parameters,
    wrap it in its node, serve the coupling topic until shutdown.

    :param make_node: called with the :class:`~conveyor_twin.split.scale.ScaleRole` and the
        node's keyword arguments (``context``, ``markers_rate``, ``step_s``, ``health``);
        returns the node.
    :return: 0 after SIGINT/SIGTERM, 1 for an invalid cell, :data:`EXIT_BACKGROUND_FAILURE`
        after a thread of the process failed.
    """
    ignore_sigint = os.environ.get(IGNORE_SIGINT_ENV) == '1'
    if ignore_sigint:  # from the start: a Ctrl-C during the set-up must not end it either
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    started = start_process(f'{role.name.lower()}node', argv)
    if started is None:
        return 1
    context, params, cell, seed = started
    scale: ScaleRole = build_scale_role(role, cell, seed=seed)
    warm_up(cell, seed)  # load the step kernels now, not during the first steps
    health = Health()
    node = make_node(scale, context=context, markers_rate=params.markers_rate,
                     step_s=cell.settings.step, health=health)
    if params.scenario:  # the coordinator checks the file; here only: does it need measures?
        from conveyor_twin.faults.scenario import load_scenario, ScenarioError
        try:
            if load_scenario(params.scenario, cell).conditional:
                scale.measure = scale.trigger_measures()
        except ScenarioError:
            pass
    executor = make_executor(context)
    executor.add_node(node)
    stop = threading.Event()
    if not ignore_sigint:
        signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    health.listeners.append(lambda failure: stop.set())
    spin_stop = threading.Event()
    spinner = health.thread(f'{node.get_name()} executor thread', spin_until, executor,
                            spin_stop)
    spinner.start()
    freeze_heap()  # no 60-80 ms full collections while stepping
    stop.wait()
    spin_stop.set()
    spinner.join(5.0)
    executor.shutdown(timeout_sec=5.0)
    node.destroy_node()
    context.try_shutdown()
    return EXIT_BACKGROUND_FAILURE if health.failed else 0
