#!/usr/bin/env python3
"""A small closed-loop controller for the twin, written as any user's ROS 2 node would be.

It stops the belt when a light barrier sees a part (its beam becomes blocked) and restarts it
0.5 s of simulation time later. Time comes from the stamps of the twin's messages, so the
controller behaves the same in realtime, fast and lockstep runs, and in replay.

Run the twin (``conveyor-twin run``) and, in another terminal with the same ROS_DOMAIN_ID::

    python examples/stop_on_barrier.py --ros-args -p barrier:=lb_infeed -p belt:=main
"""

import sys

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from conveyor_twin_msgs.msg import BeltCommand, LightBarrierEdge, LightBarrierStates

NS_PER_S = 1_000_000_000


class StopOnBarrier(Node):
    """Stop ``belt`` on a blocking edge of ``barrier``; restart after ``pause`` seconds."""

    def __init__(self, **kwargs) -> None:
        super().__init__('stop_on_barrier', **kwargs)
        self.barrier = self.declare_parameter('barrier', 'lb_infeed').value
        self.belt = self.declare_parameter('belt', 'main').value
        self.run_speed = float(self.declare_parameter('run_speed', 0.5).value)
        self.pause_ns = int(float(self.declare_parameter('pause', 0.5).value) * NS_PER_S)
        self.stopped_at_ns = None
        self.stops = 0
        self.restarts = 0
        self.sequence = 0
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.command = self.create_publisher(BeltCommand, 'belt_command', qos)
        self.create_subscription(LightBarrierEdge, 'light_barrier_edges', self.on_edge,
                                 QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        self.create_subscription(LightBarrierStates, 'light_barriers', self.on_states, qos)

    def _send(self, speed: float) -> None:
        # sender and sequence come back on command_status: this node's answers are its own
        self.sequence += 1
        self.command.publish(BeltCommand(belt=self.belt, speed=speed, sender=self.get_name(),
                                         sequence=self.sequence))

    def on_edge(self, edge: LightBarrierEdge) -> None:
        """Stop the belt when the watched beam becomes blocked while the belt runs."""
        if edge.name == self.barrier and edge.blocked and self.stopped_at_ns is None:
            self.stopped_at_ns = edge.header.stamp.sec * NS_PER_S + edge.header.stamp.nanosec
            self.stops += 1
            self._send(0.0)
            self.get_logger().info(f'{self.barrier} blocked by part {edge.part_id}: belt stop')

    def on_states(self, states: LightBarrierStates) -> None:
        """Restart the belt once the pause has elapsed in simulation time."""
        if self.stopped_at_ns is None:
            return
        now = states.header.stamp.sec * NS_PER_S + states.header.stamp.nanosec
        if now - self.stopped_at_ns >= self.pause_ns:
            self.stopped_at_ns = None
            self.restarts += 1
            self._send(self.run_speed)
            self.get_logger().info('pause over: belt restart')


def main(argv=None) -> int:
    """Spin the controller until Ctrl-C."""
    rclpy.init(args=argv)
    node = StopOnBarrier()
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
