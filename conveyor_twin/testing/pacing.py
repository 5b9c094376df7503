"""Pacing a controller process in lockstep: it says how far it has read, the harness waits.

A controller in its own process reads the twin's streams on its own time. Without pacing the
harness steps on while the controller still works through older messages, so what it commands
takes effect many steps after the state it decided on, and a timeout it measures on stamps
fires although the twin would have answered in time. With pacing
(``twin.start_controller(args, pace='my_node')``) the harness waits after every chunk until the
controller has acknowledged the chunk's last stamp and the twin has answered every command the
controller sent before that acknowledgement.

The acknowledgement is a ``diagnostic_msgs/DiagnosticStatus`` on ``lockstep_ack`` (relative to
the twin's namespace; reliable, transient local, depth 1): ``name`` the node's name, values
``stamp_ns`` (the newest stamp it has handled, [ns]) and ``sender``/``sequence`` of the last
command it published (``''``/``0`` if none). :class:`StepAck` sends it; any ROS 2 client can
send the same message.
"""

from typing import Any, Dict, Union

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

ACK_TOPIC = 'lockstep_ack'
ACK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def _ns(stamp: Union[int, Time, Any]) -> int:
    if isinstance(stamp, int):
        return stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


class StepAck:
    """The controller's side of pacing: number its commands and acknowledge what it read.

    :param node: the controller's node (its name is what ``pace=`` names)
    :param sender: the ``sender`` its commands carry (default: the node's name)
    """

    def __init__(self, node: Any, sender: str = '') -> None:
        self.name = node.get_name()
        self.sender = sender or self.name
        self.sequence = 0
        self._pub = node.create_publisher(DiagnosticStatus, ACK_TOPIC, ACK_QOS)

    def command(self, publisher: Any, msg: Any) -> None:
        """Publish a BeltCommand or ActuatorCommand with this sender and the next sequence."""
        self.sequence += 1
        msg.sender, msg.sequence = self.sender, self.sequence
        publisher.publish(msg)

    def done(self, stamp: Union[int, Time, Any]) -> None:
        """Acknowledge every message up to ``stamp`` (a ``builtin_interfaces/Time`` or [ns]):
        call it after handling a per-step message, once its commands are published."""
        self._pub.publish(DiagnosticStatus(name=self.name, values=[
            KeyValue(key='stamp_ns', value=str(_ns(stamp))),
            KeyValue(key='sender', value=self.sender),
            KeyValue(key='sequence', value=str(self.sequence))]))


class AckListener:
    """The harness's side: the latest acknowledgement of every paced node.

    :param node: the harness's probe node
    """

    def __init__(self, node: Any) -> None:
        self.acks: Dict[str, Dict[str, str]] = {}
        self._sub = node.create_subscription(DiagnosticStatus, ACK_TOPIC, self._on_ack, ACK_QOS)

    def _on_ack(self, status: DiagnosticStatus) -> None:
        self.acks[status.name] = {kv.key: kv.value for kv in status.values}

    def stamp_ns(self, name: str) -> int:
        """Return the newest stamp ``name`` acknowledged [ns] (-1 before its first)."""
        ack = self.acks.get(name)
        return int(ack.get('stamp_ns', '-1')) if ack else -1

    def last_command(self, name: str) -> tuple:
        """Return (sender, sequence) of the last command ``name`` sent before its latest
        acknowledgement (('', 0) if none)."""
        ack = self.acks.get(name) or {}
        return ack.get('sender', ''), int(ack.get('sequence', '0'))
