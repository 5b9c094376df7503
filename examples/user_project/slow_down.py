#!/usr/bin/env python3
"""A user's controller: run the belt slowly while a light barrier is blocked.

Run it against a twin (same ROS_DOMAIN_ID)::

    python slow_down.py --ros-args -p barrier:=lb_infeed -p belt:=main
"""

import sys

from conveyor_twin_msgs.msg import BeltCommand, LightBarrierStates
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy


class SlowDown(Node):
    """Command ``slow`` m/s on ``belt`` while ``barrier`` is blocked, ``fast`` m/s otherwise."""

    def __init__(self, **kwargs) -> None:
        super().__init__('slow_down', **kwargs)
        self.barrier = self.declare_parameter('barrier', 'lb_infeed').value
        self.belt = self.declare_parameter('belt', 'main').value
        self.slow = float(self.declare_parameter('slow', 0.2).value)
        self.fast = float(self.declare_parameter('fast', 0.5).value)
        self.blocked = None
        self.sequence = 0
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.command = self.create_publisher(BeltCommand, 'belt_command', qos)
        self.create_subscription(LightBarrierStates, 'light_barriers', self.on_states, qos)

    def on_states(self, states: LightBarrierStates) -> None:
        """Send a new speed whenever the watched barrier changes state."""
        blocked = states.blocked[list(states.name).index(self.barrier)]
        if blocked != self.blocked:
            if self.blocked is not None:
                speed = self.slow if blocked else self.fast
                self.sequence += 1  # sender and sequence come back on command_status
                self.command.publish(BeltCommand(belt=self.belt, speed=speed,
                                                 sender=self.get_name(), sequence=self.sequence))
            self.blocked = blocked


def main() -> int:
    """Spin the controller until Ctrl-C."""
    rclpy.init()
    node = SlowDown()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
