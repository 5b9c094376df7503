"""examples/stop_on_barrier.py as a separate process against the composed twin in lockstep.

The test steps the twin in small chunks; whenever the controller is due to react (a blocking
edge, or the end of its 0.5 s pause in sim time) it waits until the controller's command has
reached the twin before stepping on, so the outcome does not depend on the machine's speed.
"""

from pathlib import Path
import sys

from conveyor_twin_msgs.msg import BeltStates, LightBarrierEdge
import pytest
from rclpy.serialization import deserialize_message

from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.ros.compose import ComposedTwin
from conveyor_twin.wire import cdr
from test.ros.test_twin_nodes import quiet_cell
from test.ros.twin_driver import Driver, TIMEOUT
from test.ros_env import wait_for

pytestmark = pytest.mark.ros
EXAMPLE = Path(__file__).resolve().parents[2] / 'examples' / 'stop_on_barrier.py'
CHUNK = 5          # steps per step call: the controller's reaction lags at most this much
PAUSE_NS = 500_000_000


def _stamp(data: bytes) -> int:
    return int.from_bytes(data[4:8], 'little') * 10**9 + int.from_bytes(data[8:12], 'little')


def test_stop_on_barrier_stops_and_restarts_the_belt(ros_context, ros_processes, tmp_path):
    twin = ComposedTwin(quiet_cell(), seed=3, mode=TimeMode.LOCKSTEP, context=ros_context,
                        markers_rate=0.0)
    twin.start()
    driver = Driver(ros_context, name='example_probe')
    log = open(tmp_path / 'controller.log', 'w')
    ros_processes.start([sys.executable, str(EXAMPLE), '--ros-args', '-p', 'barrier:=lb_infeed',
                         '-p', 'belt:=main'], stdout=log, stderr=log)
    log.close()
    core = twin.twin
    pending = core.commands._pending  # commands received, applied at the next step
    try:
        assert driver.wait_connected()
        # the controller is matched on the edges, the barrier states and the belt command
        assert wait_for(lambda: twin.micro_node.edge_pub.get_subscription_count() >= 2
                        and twin.micro_node.barrier_pub.get_subscription_count() >= 2
                        and driver.probe.count_publishers('belt_command') >= 2,
                        TIMEOUT, driver.executor), (tmp_path / 'controller.log').read_text()
        driver.spawn('spacer', [1.8], [0.0], [0.0])
        edge_ns = restart_due_ns = None
        for _ in range(2000 // CHUNK):
            driver.step(CHUNK, chunk=CHUNK)
            received = driver.probe.received
            if edge_ns is None and received['light_barrier_edges']:
                edge = deserialize_message(received['light_barrier_edges'][0],
                                           LightBarrierEdge)
                assert edge.name == 'lb_infeed' and edge.blocked
                edge_ns = edge.header.stamp.sec * 10**9 + edge.header.stamp.nanosec
                assert wait_for(lambda: pending or core.actuation.belt_target[0] == 0.0,
                                TIMEOUT, driver.executor), 'no stop command'
            states = received['light_barriers'][-1]
            if (edge_ns is not None and restart_due_ns is None
                    and _stamp(states) - edge_ns >= PAUSE_NS):
                restart_due_ns = _stamp(states)
                assert wait_for(lambda: pending or core.actuation.belt_target[0] > 0.0,
                                TIMEOUT, driver.executor), 'no restart command'
            if restart_due_ns is not None and _stamp(states) > restart_due_ns + 300_000_000:
                break
        belts = [(_stamp(d), deserialize_message(d, BeltStates))
                 for d in driver.probe.received['belt_states']]
        stop_ns = next(t for t, b in belts if b.commanded_speed[0] == 0.0)
        restart_ns = next(t for t, b in belts if t > stop_ns and b.commanded_speed[0] > 0.0)
        assert edge_ns is not None, 'the part never reached the barrier'
        assert 0 < stop_ns - edge_ns <= (2 * CHUNK + 1) * 1_000_000
        # the belt actually stopped (speed ramps down to 0) and ran again after the pause
        assert any(b.speed[0] == 0.0 for t, b in belts if stop_ns <= t < restart_ns)
        assert PAUSE_NS <= restart_ns - edge_ns <= PAUSE_NS + (2 * CHUNK + 1) * 1_000_000
        assert belts[-1][1].commanded_speed[0] == pytest.approx(0.5)
        assert belts[-1][1].speed[0] == pytest.approx(0.5)
        last = cdr.decode_part_states(driver.probe.received['parts'][-1])
        assert last.x[0] > 2.0  # the part went on through the barrier
    finally:
        driver.close()
        twin.stop()
