"""Per-step coupling between the twin's own processes (split layout) over hidden ROS topics.

Payloads travel as ``std_msgs/UInt8MultiArray`` CDR built and parsed by hand (no per-step
message objects). Topic names start with ``_`` so ``ros2 topic list`` hides them.

Payload kinds (first byte): ``S`` step input, ``R`` reset (seed + cell file), ``P`` spawn
request, ``C`` counters request, ``D`` done (node role, step, reply bytes). The done of a step
carries the node's counters only on diagnostics steps (the ledger costs ~0.3 ms); the
coordinator asks for them (``C``) when it needs them in between (the summary).

Cells with ``macro``/``auto`` zones also couple the two scale nodes every step
(:mod:`conveyor_twin.coord.mirror`): the micro node sends its state after its step on
:data:`MICRO_STATE_TOPIC`, the macro node answers with the hand-over's edits on
:data:`EDITS_TOPIC`; both payloads are :func:`stamped` with the step.
"""

import struct
from typing import Tuple

COUPLING_TOPIC = '_coupling/to_scales'
DONE_TOPIC = '_coupling/from_scales'
MICRO_STATE_TOPIC = '_coupling/micro_state'
EDITS_TOPIC = '_coupling/edits'

STEP = b'S'
RESET = b'R'
SPAWN = b'P'
COUNTERS = b'C'
DONE = b'D'

_PREFIX = struct.Struct('<4sIII')  # encapsulation, layout.dim length, data_offset, data length
_ENCAPSULATION = b'\x00\x01\x00\x00'
_DONE = struct.Struct('<cBQ')  # kind, role, step
_STEP = struct.Struct('<Q')


def to_cdr(payload: bytes) -> bytes:
    """Wrap ``payload`` as the CDR of a ``std_msgs/UInt8MultiArray`` with no dimensions."""
    return _PREFIX.pack(_ENCAPSULATION, 0, 0, len(payload)) + payload


def from_cdr(cdr: bytes) -> bytes:
    """Return the payload of :func:`to_cdr` bytes.

    :raises ValueError: if the bytes are not such a message.
    """
    encapsulation, dims, _, length = _PREFIX.unpack_from(cdr, 0)
    if encapsulation != _ENCAPSULATION or dims != 0 or _PREFIX.size + length > len(cdr):
        raise ValueError('not a conveyor_twin coupling message')
    return bytes(cdr[_PREFIX.size:_PREFIX.size + length])


def done(role: int, step: int, reply: bytes = b'') -> bytes:
    """Return the payload acknowledging ``step`` from the scale node ``role``."""
    return _DONE.pack(DONE, role, step) + reply


def parse_done(payload: bytes) -> Tuple[int, int, bytes]:
    """Return (role, step, reply) of a :func:`done` payload."""
    _, role, step = _DONE.unpack_from(payload, 0)
    return role, step, payload[_DONE.size:]


def stamped(step: int, payload: bytes) -> bytes:
    """Return ``payload`` prefixed with ``step`` (the scale nodes' exchange)."""
    return _STEP.pack(step) + payload


def parse_stamped(payload: bytes) -> Tuple[int, bytes]:
    """Return (step, payload view) of :func:`stamped` bytes (no copy)."""
    return _STEP.unpack_from(payload, 0)[0], memoryview(payload)[_STEP.size:]
