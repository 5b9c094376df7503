"""A probe that receives contract topics raw, stamping each arrival on the monotonic clock."""

import time
from typing import Callable, Dict, Iterable, List, Optional, Tuple

from rclpy.node import Node
from rclpy.qos import QoSProfile

from conveyor_twin.record import topics as contract
from conveyor_twin.ros.record_node import message_class, subscription_qos


class RawProbe(Node):
    """Subscribe raw to contract topics (contract QoS, deep history); keep (t [ns], bytes).

    :param context: rclpy context.
    :param names: contract names (``parts``, ``/clock``, ...).
    :param depth: history depth of every subscription.
    """

    def __init__(self, context, names: Iterable[str], *, namespace: str = '',
                 depth: int = 1000, name: str = 'raw_probe') -> None:
        super().__init__(name, context=context)
        self.received: Dict[str, List[Tuple[int, bytes]]] = {}
        self._subs = []
        for spec in contract.select(list(names)):
            topic = contract.resolve(spec.name, namespace)
            log = self.received[topic] = []
            qos: QoSProfile = subscription_qos(spec.qos)
            qos.depth = max(qos.depth, depth)
            self._subs.append(self.create_subscription(
                message_class(spec.type_name), topic,
                lambda data, log=log: log.append((time.monotonic_ns(), data)), qos, raw=True))

    def data(self, topic: str) -> List[bytes]:
        """Return the bytes received on a topic, in arrival order."""
        return [d for _, d in self.received[topic]]

    def count(self, topic: str) -> int:
        """Return how many messages arrived on a topic."""
        return len(self.received[topic])


def spin_until(executor, condition: Callable[[], bool], timeout: float,
               period: float = 0.05) -> bool:
    """Spin ``executor`` until ``condition`` holds or ``timeout`` [s] passes; return it."""
    deadline = time.monotonic() + timeout
    while not condition():
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return False
        executor.spin_once(timeout_sec=min(period, remaining))
    return True


def events_executor(context) -> Optional[object]:
    """Return an EventsExecutor on ``context`` (lower per-message cost than the default)."""
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)
