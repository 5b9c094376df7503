"""A cell that stops waits until its subscribers acknowledged its last reports: the last cell
to finish publishes its ``done`` once and ends, and a subscriber whose datagram was lost would
otherwise wait for that report forever."""

import signal
import sys

import pytest

from conveyor_twin import contract
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.testing.ros_env import wait_for
from test.plant.test_plant_health import solo

TIMEOUT = 120.0   # s, a bound for a loaded machine

pytestmark = pytest.mark.ros

# A subscriber of the plant's progress in a process of its own (one that can be frozen).
SUBSCRIBER = '''
import sys
import rclpy
from rclpy.node import Node
from conveyor_twin import contract
from conveyor_twin.ros.plant_messages import CellProgress
from conveyor_twin.ros.qos import to_rclpy
rclpy.init()
node = Node('progress_listener', namespace=sys.argv[1])
node.create_subscription(CellProgress, contract.CELL_PROGRESS.name, lambda m: None,
                         to_rclpy(contract.CELL_PROGRESS.qos))
rclpy.spin(node)
'''


def test_a_stopping_cell_waits_for_its_subscribers_to_acknowledge_its_last_report(
        ros_context, ros_processes):
    from conveyor_twin.ros.plant_cell_node import PlantCellNode
    node = PlantCellNode(solo(), 'only', context=ros_context, mode=TimeMode.FAST,
                         end_step=0, streams=False)
    namespace = '/' + node.plant.namespace
    listener = ros_processes.start([sys.executable, '-c', SUBSCRIBER, namespace])
    topic = f'{namespace}/{contract.CELL_PROGRESS.name}'
    try:
        # the cell's own subscription and the listener's
        assert wait_for(lambda: node._progress_pub.get_subscription_count() == 2, TIMEOUT)
        assert node.deliver(TIMEOUT)
        listener.send_signal(signal.SIGSTOP)   # frozen: it receives and acknowledges nothing
        node.report_done()
        assert not node.deliver(0.5), f'{topic}: acknowledged by a frozen subscriber'
        listener.send_signal(signal.SIGCONT)
        assert node.deliver(TIMEOUT)
    finally:
        listener.send_signal(signal.SIGCONT)
        node.stop()
