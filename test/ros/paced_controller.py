#!/usr/bin/env python3
"""A controller process with a watchdog measured on stamps, for the pacing tests.

At the first ``belt_states`` stamped at or after ``decide_at`` [s] it commands the belt to
``speed``; it then expects to see that speed commanded in ``belt_states`` within ``timeout`` [s]
of stamps and prints ``TIMEOUT`` if it does not (a false alarm when it reads a backlog of states
stamped after its decision). With ``pace`` it acknowledges every state it handled on
``lockstep_ack`` (:class:`conveyor_twin.testing.StepAck`).
"""

import sys
import time

from conveyor_twin_msgs.msg import BeltCommand, BeltStates
import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from conveyor_twin.testing import StepAck


class PacedWatchdog(Node):
    """Command once, then watch on stamps that the twin applied it."""

    def __init__(self) -> None:
        super().__init__('paced_watchdog')
        self.decide_at = int(self.declare_parameter('decide_at', 0.05).value * 1e9)
        self.timeout = int(self.declare_parameter('timeout', 0.03).value * 1e9)
        self.speed = float(self.declare_parameter('speed', 0.3).value)
        self.work = float(self.declare_parameter('work', 0.0).value)
        pace = bool(self.declare_parameter('pace', True).value)
        self.ack = StepAck(self) if pace else None
        self.decided = None
        self.done = False
        qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        self.command = self.create_publisher(BeltCommand, 'belt_command', qos)
        self.create_subscription(BeltStates, 'belt_states', self.on_states, qos)

    def on_states(self, msg: BeltStates) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        time.sleep(self.work)  # a controller that thinks
        commanded = msg.commanded_speed[list(msg.name).index('main')]
        if self.decided is None and stamp >= self.decide_at:
            self.decided = stamp
            command = BeltCommand(belt='main', speed=self.speed)
            if self.ack is not None:
                self.ack.command(self.command, command)
            else:
                self.command.publish(command)
            print(f'decided at {stamp} ns', flush=True)
        elif self.decided is not None and not self.done:
            if commanded == self.speed:
                self.done = True
                print(f'applied {stamp - self.decided} ns after the decision', flush=True)
            elif stamp - self.decided > self.timeout:
                self.done = True
                print(f'TIMEOUT: not applied {stamp - self.decided} ns after the decision',
                      flush=True)
        if self.ack is not None:
            self.ack.done(msg.header.stamp)


def main() -> int:
    rclpy.init(args=sys.argv)
    node = PacedWatchdog()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
