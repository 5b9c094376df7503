"""CDR decoders of the contract messages that :mod:`conveyor_twin.wire.cdr` does not decode.

``BeltStates``, ``ActuatorStates`` (a header, names and two float64 arrays) and
``LightBarrierEdge``, with the bounds-checked reader of :mod:`conveyor_twin.wire.cdr`; the
arrays come back as numpy arrays. Candidates to move into ``wire/cdr.py``.
"""

from typing import NamedTuple, Tuple

import numpy as np

from conveyor_twin.wire.cdr import _Reader, CdrError


class NamedPairData(NamedTuple):
    """Decoded BeltStates [m/s] or ActuatorStates [m or rad]; arrays indexed like ``names``."""

    stamp_ns: int
    frame_id: str
    names: Tuple[str, ...]
    commanded: np.ndarray
    actual: np.ndarray


def _named_pair(data: bytes, type_name: str) -> NamedPairData:
    r = _Reader(data, type_name)
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    names = tuple(r.string() for _ in range(r.scalar('I')))
    commanded = r.array('f8')
    actual = r.array('f8')
    if not len(names) == len(commanded) == len(actual):
        msg = (f'{type_name}: {len(names)} names, {len(commanded)} commanded and '
               f'{len(actual)} actual values')
        raise CdrError(msg)
    return NamedPairData(stamp_ns, frame_id, names, commanded, actual)


def decode_belt_states(data: bytes) -> NamedPairData:
    """Decode a BeltStates message: commanded and actual speed per belt [m/s].

    :raises CdrError: on malformed data.
    """
    return _named_pair(data, 'BeltStates')


def decode_actuator_states(data: bytes) -> NamedPairData:
    """Decode an ActuatorStates message: commanded and actual position [m or rad].

    :raises CdrError: on malformed data.
    """
    return _named_pair(data, 'ActuatorStates')


class EdgeData(NamedTuple):
    """Decoded LightBarrierEdge; ``stamp_ns`` is the interpolated time of the edge [ns]."""

    stamp_ns: int
    frame_id: str
    name: str
    blocked: bool
    part_id: int


def decode_light_barrier_edge(data: bytes) -> EdgeData:
    """Decode a LightBarrierEdge message.

    :raises CdrError: on malformed data.
    """
    r = _Reader(data, 'LightBarrierEdge')
    stamp_ns = r.stamp_ns()
    frame_id = r.string()
    name = r.string()
    blocked = bool(r.scalar('B'))
    part_id = r.scalar('I')
    return EdgeData(stamp_ns, frame_id, name, blocked, part_id)
