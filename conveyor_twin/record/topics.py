"""The contract's topics as a recorder or a replayer sees them: names, types, QoS, stamps.

The table itself is :mod:`conveyor_twin.contract` (no rclpy); this module adds what recording
and replaying need around it: absolute names in a namespace (:func:`resolve`,
:func:`relative`), the selection of topics to record (:func:`select`) and, for bytes received
from another process, the simulation time they carry (:func:`stamp_ns`). Names are relative (a
namespace moves them) except ``/clock``, which is absolute as simulators publish it.

``header.stamp`` is the first 8 bytes of the payload of every stamped type (``int32 sec``,
``uint32 nanosec``), and the payload of ``rosgraph_msgs/Clock`` is the time itself. Commands
carry no time.
"""

import struct
from typing import Dict, Iterable, List, Optional

from conveyor_twin.contract import CLOCK, MARKERS, Stamp, Topic, TOPICS

__all__ = ['STAMP_BY_TYPE', 'relative', 'resolve', 'select', 'spec_of', 'stamp_ns']

_STAMP_LE = struct.Struct('<iI')
_STAMP_BE = struct.Struct('>iI')
NS_PER_S = 1_000_000_000

#: Stamp location by type, for topics known only by their type (recorded or discovered).
STAMP_BY_TYPE: Dict[str, Stamp] = {spec.type_name: spec.stamp for spec in TOPICS.values()}


def resolve(name: str, namespace: str = '') -> str:
    """Return the absolute name of a topic in a namespace.

    :param name: relative (``parts``) or absolute (``/clock``) topic name.
    :param namespace: ROS namespace (``''``, ``/`` or ``/twin``; a missing leading slash is
        added).
    :return: e.g. ``/twin/parts``, ``/clock``.
    """
    if name.startswith('/'):
        return name
    ns = '/' + namespace.strip('/') if namespace.strip('/') else ''
    return f'{ns}/{name}'


def relative(topic: str, namespace: str = '') -> str:
    """Return the contract name of an absolute topic in a namespace (inverse of :func:`resolve`).

    A topic outside the namespace (or ``/clock``) is returned unchanged.
    """
    ns = '/' + namespace.strip('/') if namespace.strip('/') else ''
    if topic != CLOCK.name and topic.startswith(ns + '/'):
        return topic[len(ns) + 1:]
    return topic


def spec_of(topic: str, namespace: str = '') -> Optional[Topic]:
    """Return the contract entry of an absolute topic in a namespace (None if not contract)."""
    return TOPICS.get(relative(topic, namespace))


def select(names: Optional[Iterable[str]] = None, *,
           markers: bool = False) -> List[Topic]:
    """Return the contract entries to record.

    :param names: relative names (``/clock`` absolute) to pick; None: every default topic.
    :param markers: add ``markers`` to the defaults.
    :raises KeyError: for a name that is not a contract topic (the message lists them).
    """
    if names is None:
        return [s for s in TOPICS.values() if s.default or (markers and s is MARKERS)]
    chosen = []
    for name in names:
        spec = TOPICS.get(name) or TOPICS.get(name.lstrip('/'))
        if spec is None and name.lstrip('/') == CLOCK.name.lstrip('/'):
            spec = CLOCK
        if spec is None:
            msg = f'{name!r} is not a contract topic; expected one of {", ".join(TOPICS)}'
            raise KeyError(msg)
        if spec not in chosen:
            chosen.append(spec)
    return chosen


def stamp_ns(stamp: str, data: bytes) -> Optional[int]:
    """Return the simulation time carried by a CDR message, or None if it carries none.

    :param stamp: :attr:`Stamp.HEADER <conveyor_twin.contract.Stamp.HEADER>` or
        ``Stamp.CLOCK`` (the time is the first field of the payload) or ``Stamp.NONE``.
    :param data: serialized message, with its 4-byte encapsulation header.
    :return: time [ns], or None (no stamp, too short, or an encapsulation other than CDR).
    """
    if not stamp or len(data) < 12:
        return None
    kind = data[1]
    if data[0] != 0 or kind not in (0, 1):
        return None
    sec, nanosec = (_STAMP_LE if kind == 1 else _STAMP_BE).unpack_from(data, 4)
    return sec * NS_PER_S + nanosec
