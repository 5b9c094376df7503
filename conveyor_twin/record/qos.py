"""Offered QoS profiles as rosbag2 stores them in the channel metadata of an MCAP recording.

rosbag2 (metadata version 9, Jazzy and Kilted) writes the key ``offered_qos_profiles`` of each
channel as the YAML dump of a list of profiles with policy names as strings
(``rosbag2_storage/qos.cpp``); ``ros2 bag play`` re-offers them. The profiles below mirror
``conveyor_twin/ros/qos.py`` without importing rclpy; durations are the RMW "infinite"
(``RMW_DURATION_INFINITE`` = 9223372036 s 854775807 ns), as a graph query reports them for
publishers that leave them unset.
"""

from dataclasses import dataclass
from typing import Sequence

_INFINITE = (9223372036, 854775807)


@dataclass(frozen=True)
class OfferedQos:
    """One offered QoS profile (policy names as rmw's ``*_to_str`` spells them)."""

    history: str = 'keep_last'
    depth: int = 100
    reliability: str = 'reliable'
    durability: str = 'volatile'
    liveliness: str = 'automatic'


#: Every-step streams: reliable, keep-last 100.
STREAM_QOS = OfferedQos()
#: Light-barrier edges: reliable, deeper history.
EDGE_QOS = OfferedQos(depth=1000)
#: /clock as simulators publish it: best effort, keep-last 1.
CLOCK_QOS = OfferedQos(depth=1, reliability='best_effort')
#: Commands.
COMMAND_QOS = OfferedQos(depth=100)
#: Diagnostics and other slow topics.
SLOW_QOS = OfferedQos(depth=10)

_BY_TYPE = {
    'rosgraph_msgs/msg/Clock': CLOCK_QOS,
    'conveyor_twin_msgs/msg/LightBarrierEdge': EDGE_QOS,
    'conveyor_twin_msgs/msg/BeltCommand': COMMAND_QOS,
    'conveyor_twin_msgs/msg/ActuatorCommand': COMMAND_QOS,
    'diagnostic_msgs/msg/DiagnosticArray': SLOW_QOS,
}


def default_qos(type_name: str) -> OfferedQos:
    """Return the profile the twin offers for a message type."""
    return _BY_TYPE.get(type_name, STREAM_QOS)


def _duration(key: str) -> str:
    return f'  {key}:\n    sec: {_INFINITE[0]}\n    nsec: {_INFINITE[1]}\n'


def profiles_yaml(profiles: Sequence[OfferedQos]) -> str:
    """Return the ``offered_qos_profiles`` text of a channel, formatted as yaml-cpp dumps it.

    :param profiles: one profile per publisher of the topic.
    """
    items = []
    for p in profiles:
        items.append(
            f'- history: {p.history}\n  depth: {p.depth}\n  reliability: {p.reliability}\n'
            f'  durability: {p.durability}\n' + _duration('deadline') + _duration('lifespan')
            + f'  liveliness: {p.liveliness}\n' + _duration('liveliness_lease_duration')
            + '  avoid_ros_namespace_conventions: false')
    return '\n'.join(items) if items else '[]'


def profile_dict(p: OfferedQos) -> dict:
    """Return a profile as the mapping rosbag2 writes into its serialized bag metadata."""
    infinite = {'sec': _INFINITE[0], 'nsec': _INFINITE[1]}
    return {'history': p.history, 'depth': p.depth, 'reliability': p.reliability,
            'durability': p.durability, 'deadline': dict(infinite),
            'lifespan': dict(infinite), 'liveliness': p.liveliness,
            'liveliness_lease_duration': dict(infinite),
            'avoid_ros_namespace_conventions': False}
