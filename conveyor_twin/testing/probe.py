"""A probe node that listens to the twin like a user's controller does (raw CDR, contract QoS)."""

import hashlib
from typing import Dict, List

from rclpy.node import Node

from conveyor_twin.ros.qos import CLOCK_QOS, EDGE_QOS, STREAM_QOS

STREAMS = {
    'parts': ('conveyor_twin_msgs.msg', 'PartStates', STREAM_QOS),
    'density': ('conveyor_twin_msgs.msg', 'DensityGrid', STREAM_QOS),
    'light_barriers': ('conveyor_twin_msgs.msg', 'LightBarrierStates', STREAM_QOS),
    'light_barrier_edges': ('conveyor_twin_msgs.msg', 'LightBarrierEdge', EDGE_QOS),
    'belt_states': ('conveyor_twin_msgs.msg', 'BeltStates', STREAM_QOS),
    'actuator_states': ('conveyor_twin_msgs.msg', 'ActuatorStates', STREAM_QOS),
    '/clock': ('rosgraph_msgs.msg', 'Clock', CLOCK_QOS),
}


def _type(module: str, name: str):
    import importlib
    return getattr(importlib.import_module(module), name)


class Probe(Node):
    """Collect every message of the twin's streams as raw bytes, per topic, in arrival order."""

    def __init__(self, context, topics=tuple(STREAMS), name: str = 'probe') -> None:
        super().__init__(name, context=context)
        self.received: Dict[str, List[bytes]] = {t: [] for t in topics}
        self._subs = []
        for topic in topics:
            module, type_name, qos = STREAMS[topic]
            self._subs.append(self.create_subscription(
                _type(module, type_name), topic,
                lambda data, t=topic: self.received[t].append(data), qos, raw=True))

    def matched(self, topics=None) -> bool:
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
