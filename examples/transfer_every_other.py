#!/usr/bin/env python3
"""A controller for the transfer cell: every other part goes to the side line.

It counts the parts that reach the light barrier in front of the transfer unit (rising edges
of ``barrier``). For parts 1, 3, 5, ... it raises the transfer unit ``transfer`` to ``lift``;
its rollers then carry the part off the main belt onto the side line. It lowers the unit again
as soon as the part left (a rising edge of ``side_barrier`` on the side line), or ``timeout``
seconds after raising it if no part arrived there, or at once when the next part (one that
must stay on the main line) reaches ``barrier`` while the unit is still up. It counts the
parts seen on each line (``side_barrier``, ``main_barrier``) and prints the counts whenever
one changes, e.g. ``counts: in 5, side 2, main 2``. Time comes from the stamps of the twin's
messages, so the controller behaves the same in realtime, fast and lockstep runs, and in
replay.

Run the twin of the transfer cell::

    conveyor-twin run --cell conveyor_twin/cell/examples/transfer.yaml --duration 30

and, in another terminal with the same ROS_DOMAIN_ID::

    python examples/transfer_every_other.py

(parameters, all optional: ``--ros-args -p transfer:=xfer -p lift:=0.02 -p barrier:=lb_main_in
-p side_barrier:=lb_side -p main_barrier:=lb_main_out -p timeout:=2.5``).
"""

import sys
from typing import Optional

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from conveyor_twin_msgs.msg import ActuatorCommand, LightBarrierEdge, LightBarrierStates

NS_PER_S = 1_000_000_000


def stamp_ns(msg) -> int:
    """Simulation time of a message's header stamp [ns]."""
    return msg.header.stamp.sec * NS_PER_S + msg.header.stamp.nanosec


class TransferEveryOther(Node):
    """Raise ``transfer`` for the odd parts at ``barrier``; lower it once the part left."""

    def __init__(self, **kwargs) -> None:
        super().__init__('transfer_every_other', **kwargs)
        self.transfer = self.declare_parameter('transfer', 'xfer').value
        self.lift = float(self.declare_parameter('lift', 0.02).value)                  # [m]
        self.barrier = self.declare_parameter('barrier', 'lb_main_in').value
        self.side_barrier = self.declare_parameter('side_barrier', 'lb_side').value
        self.main_barrier = self.declare_parameter('main_barrier', 'lb_main_out').value
        self.timeout_ns = int(float(self.declare_parameter('timeout', 2.5).value) * NS_PER_S)
        #: Parts seen at ``barrier``, at ``side_barrier`` and at ``main_barrier``.
        self.counts = {'in': 0, 'side': 0, 'main': 0}
        self.timeouts = 0          # lowered because no part reached the side line in time
        self.raised_at_ns: Optional[int] = None  # stamp of the edge it was raised for
        self.sequence = 0
        qos = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        self.command = self.create_publisher(ActuatorCommand, 'actuator_command', qos)
        self.create_subscription(LightBarrierEdge, 'light_barrier_edges', self.on_edge,
                                 QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        self.create_subscription(LightBarrierStates, 'light_barriers', self.on_states, qos)

    def _send(self, position: float) -> None:
        # sender and sequence come back on command_status: this node's answers are its own
        self.sequence += 1
        self.command.publish(ActuatorCommand(actuator=self.transfer, position=position,
                                             sender=self.get_name(), sequence=self.sequence))

    def _raise(self, now_ns: int) -> None:
        self.raised_at_ns = now_ns
        self._send(self.lift)

    def _lower(self) -> None:
        self.raised_at_ns = None
        self._send(0.0)

    def _count(self, line: str) -> None:
        self.counts[line] += 1
        c = self.counts
        print(f"counts: in {c['in']}, side {c['side']}, main {c['main']}", flush=True)

    def on_edge(self, edge: LightBarrierEdge) -> None:
        """Count rising edges; raise for odd parts, lower when the part reached the side."""
        if not edge.blocked:
            return
        if edge.name == self.barrier:
            self._count('in')
            if self.counts['in'] % 2 == 1:
                self._raise(stamp_ns(edge))
            elif self.raised_at_ns is not None:  # this part must stay on the main line
                self.get_logger().warning(f'part {edge.part_id} reached {self.barrier} with '
                                          f'{self.transfer} still raised: lowering it')
                self._lower()
        elif edge.name == self.side_barrier:
            self._count('side')
            if self.raised_at_ns is not None:
                self._lower()
        elif edge.name == self.main_barrier:
            self._count('main')

    def on_states(self, states: LightBarrierStates) -> None:
        """Lower the unit if no part reached the side line within the timeout."""
        if self.raised_at_ns is not None and stamp_ns(states) - self.raised_at_ns >= \
                self.timeout_ns:
            self.timeouts += 1
            self.get_logger().warning(f'no part reached {self.side_barrier} within '
                                      f'{self.timeout_ns / NS_PER_S:g} s: lowering '
                                      f'{self.transfer}')
            self._lower()


def main(argv=None) -> int:
    """Spin the controller until Ctrl-C; print the final counts."""
    rclpy.init(args=argv)
    node = TransferEveryOther()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        c = node.counts
        print(f"final counts: in {c['in']}, side {c['side']}, main {c['main']}, "
              f'timeouts {node.timeouts}', flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv))
