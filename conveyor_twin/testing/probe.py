"""A probe node that listens to the twin like a user's controller does (raw CDR, contract QoS)."""

import hashlib
import importlib
from typing import Any, Dict, List, Optional, Sequence

from rclpy.context import Context
from rclpy.node import Node

from conveyor_twin.ros.qos import CLOCK_QOS, COMMAND_QOS, EDGE_QOS, LATCHED_QOS, STREAM_QOS

#: The twin's streams a probe listens to by default: ``{topic: (module, type, QoS)}``.
STREAMS = {
    'parts': ('conveyor_twin_msgs.msg', 'PartStates', STREAM_QOS),
    'density': ('conveyor_twin_msgs.msg', 'DensityGrid', STREAM_QOS),
    'light_barriers': ('conveyor_twin_msgs.msg', 'LightBarrierStates', STREAM_QOS),
    'light_barrier_edges': ('conveyor_twin_msgs.msg', 'LightBarrierEdge', EDGE_QOS),
    'belt_states': ('conveyor_twin_msgs.msg', 'BeltStates', STREAM_QOS),
    'actuator_states': ('conveyor_twin_msgs.msg', 'ActuatorStates', STREAM_QOS),
    '/clock': ('rosgraph_msgs.msg', 'Clock', CLOCK_QOS),
    'faults': ('conveyor_twin_msgs.msg', 'FaultState', LATCHED_QOS),
}
#: More topics a probe can listen to: the twin's answer to each command, and the commands of
#: every controller.
COMMAND_TOPICS = {
    'command_status': ('diagnostic_msgs.msg', 'DiagnosticStatus', STREAM_QOS),
    'belt_command': ('conveyor_twin_msgs.msg', 'BeltCommand', COMMAND_QOS),
    'actuator_command': ('conveyor_twin_msgs.msg', 'ActuatorCommand', COMMAND_QOS),
}


def _type(module: str, name: str) -> Any:
    return getattr(importlib.import_module(module), name)


class Probe(Node):
    """Collect every message of the twin's streams as raw bytes, per topic, in arrival order.

    :param context: rclpy context the node lives in
    :param topics: topics to listen to (keys of :data:`STREAMS` and :data:`COMMAND_TOPICS`)
    :param name: node name
    """

    def __init__(self, context: Context, topics: Sequence[str] = tuple(STREAMS),
                 name: str = 'probe') -> None:
        super().__init__(name, context=context)
        self.received: Dict[str, List[bytes]] = {t: [] for t in topics}
        self._subs = []
        for topic in topics:
            module, type_name, qos = {**STREAMS, **COMMAND_TOPICS}[topic]
            self._subs.append(self.create_subscription(
                _type(module, type_name), topic,
                lambda data, t=topic: self.received[t].append(data), qos, raw=True))

    def matched(self, topics: Optional[Sequence[str]] = None) -> bool:
        """True once every listened topic (or those given) has a publisher."""
        wanted = topics or self.received
        return all(self.count_publishers(t) > 0 for t in wanted)

    def digest(self, topic: str) -> str:
        """SHA-256 of every message received on ``topic``, concatenated."""
        h = hashlib.sha256()
        for data in self.received[topic]:
            h.update(len(data).to_bytes(4, 'little'))
            h.update(data)
        return h.hexdigest()
