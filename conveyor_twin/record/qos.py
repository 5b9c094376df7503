"""Offered QoS profiles as rosbag2 stores them in the channel metadata of an MCAP recording.

rosbag2 (metadata version 9, Jazzy and Kilted) writes the key ``offered_qos_profiles`` of each
channel as the YAML dump of a list of profiles with policy names as strings
(``rosbag2_storage/qos.cpp``); ``ros2 bag play`` re-offers them. The profiles are those of the
contract table (:mod:`conveyor_twin.contract`); durations are the RMW "infinite"
(``RMW_DURATION_INFINITE`` = 9223372036 s 854775807 ns), as a graph query reports them for
publishers that leave them unset.
"""

from typing import Sequence

from conveyor_twin.contract import (CLOCK_QOS, COMMAND_QOS, EDGE_QOS, OfferedQos, SLOW_QOS,
                                    STREAM_QOS, TOPICS)

__all__ = ['CLOCK_QOS', 'COMMAND_QOS', 'EDGE_QOS', 'OfferedQos', 'SLOW_QOS', 'STREAM_QOS',
           'default_qos', 'profile_dict', 'profiles_yaml']

_INFINITE = (9223372036, 854775807)

_BY_TYPE = {t.type_name: t.qos for t in TOPICS.values()}


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
