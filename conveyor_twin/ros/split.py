"""The split layout's coordinator process: micro, macro and coordinator nodes as three processes.

``scale_coordinator`` (this module's :func:`coordinator_main`) drives time; its one stage is
the two scale processes (:class:`~conveyor_twin.split.remote.RemoteStage`), which every step
receive the step input over the coupling topic and report it done. :class:`CouplingTransport`
only moves those bytes between ROS and the stage. The processes are started by
:func:`conveyor_twin.split.launch.launch` (``conveyor-twin run --split``, the testing harness),
with ``macro``/``auto`` zones the scale processes also exchange the hand-over every step
(:mod:`conveyor_twin.split.mirror`), so the streams are bit-identical to the composed layout's.
"""

import json
import signal
import sys
import threading
import time
from typing import Callable, List, Optional, Set

from rclpy.context import Context
from rclpy.node import Node
from std_msgs.msg import UInt8MultiArray

from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE, Health
from conveyor_twin.ros.compat import make_executor, spin_until
from conveyor_twin.ros.coordinator_node import CoordinatorNode
from conveyor_twin.ros.qos import COUPLING_QOS
from conveyor_twin.ros.sim_attach import attach_split_sim_interfaces
from conveyor_twin.ros.standalone import start_process
from conveyor_twin.split import topics
from conveyor_twin.split.launch import check_scale_processes, scale_pids_from_env, SUMMARY_PREFIX
from conveyor_twin.split.remote import RemoteStage
from conveyor_twin.split.roles import CoordinatorRole

# s for the scale processes to appear and match: each loads its kernels first (~20 s on a
# loaded 2-core machine); known scale processes that die meanwhile end the wait at once
SCALE_CONNECT_TIMEOUT = 120.0
WATCH_PERIOD = 0.05  # s between two checks of the run and the scale processes


class CouplingTransport:
    """The coordinator's end of the coupling topics: a node of its own that publishes the
    payloads and hands every reply to :attr:`receiver` (the remote stage). It is spun by its
    own executor thread: a step, reset or spawn service callback of the coordinator node waits
    for the replies, so they cannot share that node's executor."""

    def __init__(self, context: Context, namespace: Optional[str] = None) -> None:
        self.node = Node('_scale_coordinator_coupling', context=context, namespace=namespace,
                         start_parameter_services=False)
        self._context = context
        self.receiver: Callable[[bytes], None] = self._unbound
        self._pub = self.node.create_publisher(UInt8MultiArray, topics.COUPLING_TOPIC,
                                               COUPLING_QOS)
        self._sub = self.node.create_subscription(UInt8MultiArray, topics.DONE_TOPIC,
                                                  lambda data: self.receiver(data),
                                                  COUPLING_QOS, raw=True)

    def _unbound(self, data: bytes) -> None:
        raise RuntimeError('a scale node replied before the coordinator had a remote stage')

    def send(self, data: bytes) -> None:
        """Publish CDR bytes to the scale nodes."""
        self._pub.publish(data)

    def connected(self, peers: int) -> bool:
        """True once ``peers`` scale nodes are matched both ways: our writer sees their
        readers, our reader sees their writers."""
        return (self._pub.get_subscription_count() >= peers
                and self._sub.get_publisher_count() >= peers)

    def alive(self) -> bool:
        """False once the context shut down."""
        return self._context.ok()

    def node_names(self) -> Set[str]:
        """The names of the nodes in the ROS graph."""
        return {name for name, _ in self.node.get_node_names_and_namespaces()}


def _wait_for_scales(remote: RemoteStage, health: Health, stop: threading.Event) -> bool:
    """Wait up to :data:`SCALE_CONNECT_TIMEOUT` until the scale nodes are connected; return
    True if so. A scale process that ends meanwhile is reported; it, or ``stop``, ends the wait."""
    deadline = time.monotonic() + SCALE_CONNECT_TIMEOUT
    while time.monotonic() < deadline and not stop.is_set():
        if remote.wait_connected(min(0.25, max(0.0, deadline - time.monotonic()))):
            return True
        check_scale_processes(health, remote.pids)
    return False


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
    transport = CouplingTransport(context)
    role = CoordinatorRole(cell, seed=seed, transport=transport, pids=scale_pids_from_env())
    remote = role.remote
    runner = Runner(role.twin, params.mode, max_steps=max_steps)
    health = role.twin.health
    node = CoordinatorNode(role.twin, runner, context=context, spawn=role.spawn,
                           holds_part=remote.holds_part, counters=remote.counters,
                           refresh=remote.counters)
    remote.warn = node.get_logger().warning
    sim_interfaces = attach_split_sim_interfaces(node, context)  # no entities: parts are remote
    if scenario is not None:  # triggers read what the scale nodes measure after each step
        role.arm_scenario(scenario)
    executor = make_executor(context)
    executor.add_node(node)
    coupling_executor = make_executor(context)
    coupling_executor.add_node(transport.node)
    spin_stop = threading.Event()
    spinners = [health.thread(name, spin_until, ex, spin_stop)
                for name, ex in (('executor thread', executor),
                                 ('coupling executor thread', coupling_executor))]
    for spinner in spinners:
        spinner.start()
    if sim_interfaces is not None:
        sim_interfaces.start()
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
    if code == 0 and not _wait_for_scales(remote, health, stop):
        if not health.failed and not stop.is_set():
            node.get_logger().error('micro_simulator and macro_simulator did not connect '
                                    f'within {SCALE_CONNECT_TIMEOUT:g} s')
            code = 1
    elif code == 0:
        runner.start()
        while not stop.is_set():
            if params.mode is not TimeMode.LOCKSTEP and not runner.running:
                break
            check_scale_processes(health, remote.pids)
            stop.wait(WATCH_PERIOD)
        runner.stop()
    if sim_interfaces is not None:  # no step on request after the run
        sim_interfaces.stop()
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
    transport.node.destroy_node()
    node.destroy_node()
    context.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(coordinator_main())
