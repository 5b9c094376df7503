"""A probe node that listens to the twin like a user's controller does (raw CDR, contract QoS)."""

import hashlib
from typing import Dict, List, Optional, Sequence

from rclpy.context import Context
from rclpy.node import Node

from conveyor_twin import contract
from conveyor_twin.contract import Topic
from conveyor_twin.ros.endpoints import create_subscription

#: The twin's streams a probe listens to by default (all but ``diagnostics`` and ``markers``):
#: ``{topic name: contract entry}``.
STREAMS: Dict[str, Topic] = {t.name: t for t in contract.STREAMS
                             if t not in (contract.DIAGNOSTICS, contract.MARKERS)}
#: More topics a probe can listen to: the twin's answer to each command, and the commands of
#: every controller.
COMMAND_TOPICS: Dict[str, Topic] = {t.name: t for t in contract.REPLIES + contract.COMMANDS}


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
            self._subs.append(create_subscription(
                self, {**STREAMS, **COMMAND_TOPICS}[topic],
                lambda data, t=topic: self.received[t].append(data), raw=True))

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
