"""What the two scale nodes share: the split layout's coupling topics and the markers cadence."""

import time
from typing import Optional

from rclpy.node import Node
from std_msgs.msg import UInt8MultiArray

from conveyor_twin.health import Health
from conveyor_twin.ros import qos
from conveyor_twin.ros.params import declare_twin_parameters
from conveyor_twin.ros.qos import COUPLING_QOS, raw_publish
from conveyor_twin.split import topics
from conveyor_twin.split.scale import ScaleRole

CONNECT_PERIOD = 0.01  # s between checks that the scale exchange is matched (split layout)
DONE_MATCH_TIMEOUT = 10.0  # s the first reply waits for its writer to see the coordinator


class ScaleNode(Node):
    """A node that owns a scale stage and publishes its streams after every step.

    Composed, the node publishes its part of the twin's frames (a sink of the shared output);
    split (``server``: the process's :class:`~conveyor_twin.split.scale.ScaleRole`), the node
    only moves bytes: the coordinator's payloads and the other scale's hand-over to the role,
    the role's replies and hand-over to their topics (it is the role's
    :class:`~conveyor_twin.split.scale.ScaleLink`). Nodes that hand parts over to the other
    scale serve the coordinator only once that exchange is matched (:meth:`peers_matched`).

    :param stage: the scale's core wrapper.
    :param server: split layout: the role this node serves; None: composed.
    :param markers_rate: MarkerArray rate [Hz]; 0 disables markers.
    :param health: where the node's own threads report a failure (composed: the twin's; a
        scale process: the process's); None: a health of the node's own.
    """

    def __init__(self, name: str, stage, *, context=None,
                 namespace: Optional[str] = None, server: Optional[ScaleRole] = None,
                 markers_rate: float = 30.0, step_s: float = 1e-3,
                 parameter_overrides=None, health: Optional[Health] = None) -> None:
        super().__init__(name, context=context, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        self.health = health if health is not None else Health()
        self.stage = stage
        self.server = server
        self.parameters = declare_twin_parameters(self, step_s=step_s)
        self.markers_every = (max(1, round(1.0 / (markers_rate * step_s)))
                              if markers_rate > 0 else 0)
        self._connect_timer = None
        if server is None:
            return
        self._done_pub = self.create_publisher(UInt8MultiArray, topics.DONE_TOPIC, COUPLING_QOS)
        if server.exchanges:
            out_topic, in_topic = topics.EXCHANGE_TOPICS[server.role]
            self.exchange_pub = self.create_publisher(UInt8MultiArray, out_topic, COUPLING_QOS)
            self.send_exchange = raw_publish(self.exchange_pub, self.get_logger())
            self._exchange_sub = self.create_subscription(
                UInt8MultiArray, in_topic, server.on_exchange, COUPLING_QOS, raw=True)
        server.serve(self)

    def serve_coordinator(self) -> None:
        """Split layout: subscribe to the coordinator's payloads, at once if this node has no
        exchange with the other scale node, else once it is matched (the coordinator waits for
        that subscription before its first step). Subclasses call it at the end of their
        constructor."""
        if self.server is None:
            return
        if self.peers_matched():
            self._subscribe_coordinator()
        else:
            self._connect_timer = self.create_timer(CONNECT_PERIOD, self._connect)

    def peers_matched(self) -> bool:
        """Return True once the exchange with the other scale node (if any) is matched both
        ways: our writer sees its reader, our reader sees its writer."""
        return self.exchange_pub is None or (self.exchange_pub.get_subscription_count() >= 1
                                             and self._exchange_sub.get_publisher_count() >= 1)

    def _connect(self) -> None:
        if self._connect_timer.is_canceled() or not self.peers_matched():
            return
        self._connect_timer.cancel()  # (destroying a timer inside its own callback is unsafe)
        self._subscribe_coordinator()

    def _subscribe_coordinator(self) -> None:
        self.create_subscription(UInt8MultiArray, topics.COUPLING_TOPIC,
                                 self.server.on_coupling, COUPLING_QOS, raw=True)

    # -- the role's link (split layout) ----------------------------------------------------
    def send_done(self, data: bytes) -> None:
        """Publish a ``done`` reply to the coordinator (the first one once it can arrive)."""
        if not self._done_matched:
            self._done_matched = self._wait_done_matched()
        self._done_pub.publish(data)

    def publish_failures(self) -> int:
        """Return the publishes the middleware refused so far."""
        return qos.publish_failures(self)

    def error(self, text: str) -> None:
        """Log a protocol error."""
        self.get_logger().error(text)

    def _wait_done_matched(self) -> bool:
        """Wait until the reply writer has matched the coordinator's reader; return True if
        so. Discovery is not symmetric: the coordinator can see this node's writer (and send
        its first payload) before this writer sees the coordinator's reader, and a volatile
        reliable writer never delivers what it published before that match, so the first
        reply would be lost. Discovery runs in the middleware's threads: waiting here in a
        callback is safe."""
        deadline = time.monotonic() + DONE_MATCH_TIMEOUT
        while self._done_pub.get_subscription_count() < 1:
            if time.monotonic() > deadline:
                self.get_logger().warning('the coordinator does not see the step replies yet; '
                                          'replying anyway')
                return False
            time.sleep(0.005)
        return True

    _done_matched = False
    exchange_pub = None  # the hand-over exchange's writer (split layout, coupled cells)
