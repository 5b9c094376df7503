"""A handshake that tells a reader when the twin's writers reach it, before the first step.

Discovery is not symmetric: a reader in another process can see the twin's writer (its own side
matched) before that writer sees the reader, and a reliable volatile writer never delivers
what it published before its side matched. A lockstep driver that steps as soon as its readers
see the twin would then wait for messages that were sent to nobody.

So a reader (the testing harness's driver) publishes a hello on :data:`HELLO_TOPIC`: a
``diagnostic_msgs/DiagnosticStatus`` whose ``name`` is its node's fully qualified name and whose
value ``topics`` lists the resolved topics it reads, comma-separated. Every node of the twin
that publishes streams runs a :class:`HandshakeResponder`; once each of its writers of those
topics has matched every compatible reader its graph shows, the hello's node among them, it
answers on :data:`READY_TOPIC` with its own fully qualified name as ``name`` and the reader's
as value ``reader``. Both topics are hidden, reliable and latched, so the order in which the
two sides start does not matter.
"""

from typing import Any, Dict, Iterable, Tuple

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.qos import (DurabilityPolicy, qos_check_compatible, QoSCompatibility, QoSProfile,
                       ReliabilityPolicy)

HELLO_TOPIC = '_lockstep/hello'
READY_TOPIC = '_lockstep/ready'
HANDSHAKE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
POLL_PERIOD = 0.01  # s between two checks of the writers' matches while a hello is pending


def node_name(namespace: str, name: str) -> str:
    """Return the fully qualified name of a node (``/ns/name``)."""
    return f'{namespace.rstrip("/")}/{name}'


def hello(reader: str, topics: Iterable[str]) -> DiagnosticStatus:
    """Return the hello of the node ``reader`` (fully qualified) that reads resolved
    ``topics``."""
    return DiagnosticStatus(name=reader, values=[KeyValue(key='topics', value=','.join(topics))])


def value(status: DiagnosticStatus, key: str) -> str:
    """Return the value of ``key`` in a hello or ready message ('' if it has none)."""
    return next((kv.value for kv in status.values if kv.key == key), '')


def writers_reach(node: Any, reader: str, topics: Tuple[str, ...]) -> bool:
    """True when each writer of ``node`` on one of ``topics`` has matched every compatible
    reader ``node``'s graph shows on its topic, one of them of the node ``reader``.

    The graph learns of a remote reader as the middleware pairs it with the local writers, so
    a reader the graph shows and the writer has not matched yet is counted as missing."""
    for publisher in node.publishers:
        if publisher.topic_name not in topics:
            continue
        infos = node.get_subscriptions_info_by_topic(publisher.topic_name)
        if not any(node_name(i.node_namespace, i.node_name) == reader for i in infos):
            return False
        compatible = [i for i in infos if qos_check_compatible(
            publisher.qos_profile, i.qos_profile)[0] != QoSCompatibility.ERROR]
        if publisher.get_subscription_count() < len(compatible):
            return False
    return True


class HandshakeResponder:
    """Answer every hello once ``node``'s writers of the hello's topics reach its reader.

    :param node: an rclpy node of the twin; its publishers are looked at when a hello is
        pending, so publishers created after this responder count too.
    """

    def __init__(self, node: Any) -> None:
        self._node = node
        self._name = node.get_fully_qualified_name()
        self._pending: Dict[str, Tuple[str, ...]] = {}
        self._ready = node.create_publisher(DiagnosticStatus, READY_TOPIC, HANDSHAKE_QOS)
        self._hellos = node.create_subscription(DiagnosticStatus, HELLO_TOPIC, self._on_hello,
                                                HANDSHAKE_QOS)
        self._timer = None

    def _on_hello(self, status: DiagnosticStatus) -> None:
        self._pending[status.name] = tuple(t for t in value(status, 'topics').split(',') if t)
        if self._timer is None:
            self._timer = self._node.create_timer(POLL_PERIOD, self._poll)
        else:
            self._timer.reset()
        self._poll()

    def _poll(self) -> None:
        for reader, topics in list(self._pending.items()):
            if writers_reach(self._node, reader, topics):
                del self._pending[reader]
                self._ready.publish(DiagnosticStatus(
                    name=self._name, values=[KeyValue(key='reader', value=reader)]))
        if not self._pending:
            self._timer.cancel()  # (destroying a timer inside its own callback is unsafe)


class HandshakeReader:
    """The reader's side: say hello for ``topics``, then tell when every node that writes
    them has answered.

    :param node: the reader's rclpy node (the hello names it).
    :param topics: the resolved topics it reads from the twin.
    """

    def __init__(self, node: Any, topics: Iterable[str]) -> None:
        self._node = node
        self.name = node.get_fully_qualified_name()
        self.topics = tuple(topics)
        self.answered: set = set()
        self._readies = node.create_subscription(DiagnosticStatus, READY_TOPIC, self._on_ready,
                                                 HANDSHAKE_QOS)
        self._hello = node.create_publisher(DiagnosticStatus, HELLO_TOPIC, HANDSHAKE_QOS)
        self._hello.publish(hello(self.name, self.topics))

    def _on_ready(self, status: DiagnosticStatus) -> None:
        if value(status, 'reader') == self.name:
            self.answered.add(status.name)

    def writers(self) -> set:
        """Return the nodes the graph shows writing one of :attr:`topics` (fully qualified)."""
        return {node_name(i.node_namespace, i.node_name) for t in self.topics
                for i in self._node.get_publishers_info_by_topic(t)} - {self.name}

    def reached(self) -> bool:
        """True once some node writes the topics and every one of them has answered."""
        writers = self.writers()
        return bool(writers) and writers <= self.answered
