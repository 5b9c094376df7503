#!/usr/bin/env python3
"""A watchdog controller: stops the belt when a light barrier stays blocked too long.

A part passes a light barrier in a fraction of a second. If the beam stays blocked for longer
than ``timeout`` seconds of simulation time, either the sensor is stuck or a part is jammed in
front of it: the controller stops ``belt``, latches the alarm (it never restarts the belt by
itself) and logs an error naming the barrier. Time comes from the stamps of the twin's
messages, so it behaves the same in realtime, fast and lockstep runs.

Run the twin with a fault scenario (``conveyor-twin run --scenario stuck.yaml``) and, in
another terminal with the same ROS_DOMAIN_ID::

    python examples/stop_on_fault.py --ros-args -p barrier:=lb_exit -p timeout:=1.0
"""

import sys

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from conveyor_twin_msgs.msg import BeltCommand, LightBarrierStates

NS_PER_S = 1_000_000_000


class StopOnFault(Node):
    """Stop ``belt`` once ``barrier`` has been blocked for ``timeout`` seconds."""

    def __init__(self, **kwargs) -> None:
        super().__init__('stop_on_fault', **kwargs)
        self.barrier = self.declare_parameter('barrier', 'lb_exit').value
        self.belt = self.declare_parameter('belt', 'main').value
        self.timeout_ns = int(float(self.declare_parameter('timeout', 1.0).value) * NS_PER_S)
        self.blocked_since_ns = None
        self.alarm_ns = None  # simulation time the belt was stopped
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.command = self.create_publisher(BeltCommand, 'belt_command', qos)
        self.create_subscription(LightBarrierStates, 'light_barriers', self.on_states, qos)

    def on_states(self, states: LightBarrierStates) -> None:
        """Track how long the barrier has been blocked; stop the belt past the timeout."""
        if self.alarm_ns is not None:
            return
        now = states.header.stamp.sec * NS_PER_S + states.header.stamp.nanosec
        blocked = states.blocked[list(states.name).index(self.barrier)]
        if not blocked:
            self.blocked_since_ns = None
            return
        if self.blocked_since_ns is None:
            self.blocked_since_ns = now
        elif now - self.blocked_since_ns >= self.timeout_ns:
            self.alarm_ns = now
            self.command.publish(BeltCommand(belt=self.belt, speed=0.0))
            self.get_logger().error(
                f'{self.barrier} blocked for {(now - self.blocked_since_ns) / NS_PER_S:.3f} s: '
                f'stuck sensor or jam; belt {self.belt} stopped')


def main(argv=None) -> int:
    """Run the watchdog until Ctrl-C."""
    rclpy.init(args=argv)
    node = StopOnFault()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
