"""QoS profiles of the contract as rclpy profiles, and the raw publisher of the streams.

The profiles are defined once, without rclpy, in the contract table
(:mod:`conveyor_twin.contract`); this module turns them into ``rclpy.qos.QoSProfile``.
"""

from rclpy._rclpy_pybind11 import RCLError
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from conveyor_twin import contract as offered

_HISTORY = {'keep_last': HistoryPolicy.KEEP_LAST, 'keep_all': HistoryPolicy.KEEP_ALL}
_RELIABILITY = {'reliable': ReliabilityPolicy.RELIABLE,
                'best_effort': ReliabilityPolicy.BEST_EFFORT}
_DURABILITY = {'volatile': DurabilityPolicy.VOLATILE,
               'transient_local': DurabilityPolicy.TRANSIENT_LOCAL}


def to_rclpy(profile: offered.OfferedQos) -> QoSProfile:
    """Return the rclpy profile of an offered profile."""
    return QoSProfile(history=_HISTORY[profile.history], depth=profile.depth,
                      reliability=_RELIABILITY[profile.reliability],
                      durability=_DURABILITY[profile.durability])


#: Every-step streams: reliable, keep-last 100, so best-effort and reliable subscribers can both
#: attach and a subscriber in another process loses nothing at 1 kHz.
STREAM_QOS = to_rclpy(offered.STREAM_QOS)
#: Light-barrier edges: reliable with a deeper history.
EDGE_QOS = to_rclpy(offered.EDGE_QOS)
#: /clock as simulators publish it (rclcpp::ClockQoS): best effort, keep-last 1.
CLOCK_QOS = to_rclpy(offered.CLOCK_QOS)
#: Commands from controllers.
COMMAND_QOS = to_rclpy(offered.COMMAND_QOS)
#: Diagnostics (1 Hz) and markers (viewer rate).
SLOW_QOS = to_rclpy(offered.SLOW_QOS)
#: The active faults: latched (transient local, keep-last 100).
LATCHED_QOS = to_rclpy(offered.LATCHED_QOS)
#: Per-step coupling between the twin's own processes (split layout): nothing may be lost.
COUPLING_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)


class RawPublisher:
    """Publish CDR ``bytes`` on ``publisher`` without rclpy's per-call wrapper (a
    context-manager entry and two isinstance checks, ~10 us each time here).

    A publish the middleware refuses is counted in :attr:`failures` and logged (first one,
    then every 1000th), never raised: Fast DDS refuses a sample when a slow reliable subscriber
    in another process has not taken the older ones (measured here: 101 of 6000 back-to-back
    1000-part messages), and one such subscriber must not stop the simulation.

    Only for the stepping thread's streams: the nodes are destroyed only after the stepping
    has stopped, which is what rclpy's handle guard protects against.
    """

    __slots__ = ('publisher', 'send', 'failures', '_logger')

    def __init__(self, publisher, logger=None) -> None:
        self.publisher = publisher
        self.send = publisher.handle.publish_raw
        self.failures = 0
        self._logger = logger

    def __call__(self, data: bytes) -> None:
        try:
            self.send(data)
        except RCLError as exc:
            self.failures += 1
            if self._logger is not None and self.failures % 1000 == 1:
                self._logger.warning(
                    f'{self.publisher.topic_name}: {self.failures} publish(es) refused by the '
                    f'middleware so far (a subscriber does not keep up?): {exc}')


def raw_publish(publisher, logger=None) -> RawPublisher:
    """Return a :class:`RawPublisher` of ``publisher`` (logging refusals to ``logger``)."""
    return RawPublisher(publisher, logger)


def publish_failures(node) -> int:
    """Return the refused publishes of every :class:`RawPublisher` attribute of ``node`` (and
    of the publishers of a frame publisher attribute, which has a ``raw_publishers`` tuple)."""
    total = 0
    for p in vars(node).values():
        if isinstance(p, RawPublisher):
            total += p.failures
        else:
            total += sum(r.failures for r in getattr(p, 'raw_publishers', ()))
    return total
