"""QoS profiles of the contract (architecture.md, ROS interface) as rclpy profiles.

The profiles are defined once, without rclpy, in :mod:`conveyor_twin.record.qos` (recordings
store them as rosbag2 does); this module turns them into ``rclpy.qos.QoSProfile``.
"""

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from conveyor_twin.record import qos as offered

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
#: Per-step coupling between the twin's own processes (split layout): nothing may be lost.
COUPLING_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)


def raw_publish(publisher):
    """Return a function publishing CDR ``bytes`` on ``publisher`` without rclpy's per-call
    wrapper (a context-manager entry and two isinstance checks, ~10 us each time here).

    Only for the stepping thread's every-step streams: the nodes are destroyed only after the
    stepping has stopped, which is what the wrapper's handle guard protects against.
    """
    return publisher.handle.publish_raw
