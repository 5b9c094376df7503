"""In realtime the composed twin publishes every frame's streams from a thread of its own, in
order and none dropped, and builds its 1 Hz diagnostics there (off the step)."""

import pytest
from diagnostic_msgs.msg import DiagnosticArray

from conveyor_twin import contract
from conveyor_twin.cell import load_cell
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.ros.compose import ComposedTwin
from conveyor_twin.ros.endpoints import create_subscription
from conveyor_twin.testing.ros_env import wait_for

pytestmark = pytest.mark.ros
WAIT = 120.0  # s: generous budget for a realtime twin to load its kernels and step


def _values(array: DiagnosticArray) -> dict:
    (status,) = [s for s in array.status if s.name == 'conveyor_twin: scale_coordinator']
    return {v.key: v.value for v in status.values}


def test_every_stepped_frame_is_published_and_diagnostics_come_once_a_second(ros_context):
    import rclpy
    twin = ComposedTwin(load_cell(), seed=1, mode=TimeMode.REALTIME, context=ros_context,
                        markers_rate=0.0)
    assert twin.publisher is not None
    assert twin.publisher in twin.output.sinks  # the nodes' publishers sit behind it
    assert not any(n.streams in twin.output.sinks
                   for n in (twin.coordinator, twin.micro_node, twin.macro_node))
    node = rclpy.create_node('diagnostics_reader', context=ros_context)
    received = []
    create_subscription(node, contract.DIAGNOSTICS, received.append)
    executor = rclpy.executors.SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    twin.start()
    try:
        assert wait_for(lambda: executor.spin_once(timeout_sec=0.05) or len(received) >= 3,
                        WAIT)
    finally:
        twin.stop()
        executor.shutdown()
        node.destroy_node()
    relay = twin.publisher
    assert relay.delivered == twin.runner.steps_done and relay.dropped == 0
    assert relay.pending == 0
    steps = [int(_values(m)['step']) for m in received]
    assert steps == sorted(steps) and len(set(steps)) == len(steps)
    stamps = [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in received]
    # each is stamped with the step it describes (1 ms steps)
    assert stamps == [s * 1_000_000 for s in steps]
