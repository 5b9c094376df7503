"""The split layout's protocol: every payload the twin's own processes exchange (no ROS imports).

Split over processes, the coordinator and the two scale nodes talk over hidden topics of type
``std_msgs/UInt8MultiArray``, whose CDR is built and parsed here by hand (:func:`to_cdr`,
:func:`from_cdr`: no per-step message objects). All numbers are little-endian.

Coordinator -> scale nodes (first byte: the kind):

- ``S`` step: :func:`step_payload` (step, time [ns], belt speeds, actuator positions, then the
  step's fault events as uint32 length + UTF-8 JSON, length 0 on the usual step without any, as
  :func:`pack_step_input`);
- ``R`` reset: :func:`reset_payload` (uint64 seed, cell file as UTF-8, empty: the current cell);
- ``P`` spawn: :func:`spawn_payload` (uint16 part type index, then x, y, yaw as float64 rows);
- ``C`` counters request (no body).

Scale nodes -> coordinator: ``D`` done, :func:`done` (uint8 role: a
:class:`~conveyor_twin.coord.layout.Role`, uint64 step, reply bytes). The
reply of a step carries the node's counters (:func:`encode_counters`) on diagnostics steps only
(the micro node's reply starts with the step's actuator loads, :func:`with_loads`, when the
cell has actuators);
the reply of a spawn is :func:`spawn_reply` / :func:`spawn_error` from the micro node.

Micro node <-> macro node (cells with ``macro``/``auto`` zones), each :func:`stamped` with the
step: the micro state after the micro step (:func:`encode_state`: ``counters`` (int64 x
C_COUNTERS), ``sink_count`` (int64 per sink), ``act_state``, ``act_verts`` (float64, fixed
shapes), then ``ids[:n]`` (uint32), ``part_type[:n]`` (uint16), ``P[:, :n]`` (float64, rows x
n; ``n = counters[C_N]``)), and the hand-over's reply: the edit log (uint32 record count, then
records ``b'A' uint32 k`` + ids, types, ``P`` rows of ``k`` appended parts, or ``b'R' uint32 k``
+ ``k`` uint32 row indices removed, :func:`append_record` / :func:`remove_record`), then the
light barriers of ``macro`` zones (:func:`encode_barriers`: uint32 count + ``(int64 index,
uint8 blocked, int64 edge_count)`` each, uint32 count + ``(int64 index, uint8 blocked, float64
time [s])`` per edge of the step).
"""

import json
import struct
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.coord.layout import Role
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.faults.book import FaultEvent
from conveyor_twin.micro.sim import MicroSim
from conveyor_twin.micro.state import C_ENTERED, C_N, C_NEXT_ID, P_ROWS

STEP = b'S'
RESET = b'R'
SPAWN = b'P'
COUNTERS = b'C'
PART_QUERY = b'Q'  # does the micro scale hold a part of this id now? (part_jam requests)
DONE = b'D'
APPEND = b'A'
REMOVE = b'R'

_PREFIX = struct.Struct('<4sIII')  # encapsulation, layout.dim length, data_offset, data length
_ENCAPSULATION = b'\x00\x01\x00\x00'
_DONE = struct.Struct('<cBQ')  # kind, role, step
_STAMP = struct.Struct('<Q')
_STEP_HEADER = struct.Struct('<QqII')  # step, time_ns, number of belts, number of actuators
_U32 = struct.Struct('<I')
_RECORD = struct.Struct('<cI')
_BARRIER = np.dtype([('index', '<i8'), ('blocked', 'u1'), ('edge_count', '<i8')])
_EDGE = np.dtype([('index', '<i8'), ('blocked', 'u1'), ('time', '<f8')])


# --- framing ---
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


def done(role: Role, step: int, reply: bytes = b'') -> bytes:
    """Return the payload acknowledging ``step`` from the scale node ``role``."""
    return _DONE.pack(DONE, role, step) + reply


def parse_done(payload: bytes) -> Tuple[int, int, bytes]:
    """Return (role, step, reply) of a :func:`done` payload."""
    _, role, step = _DONE.unpack_from(payload, 0)
    return role, step, payload[_DONE.size:]


def stamped(step: int, payload: bytes) -> bytes:
    """Return ``payload`` prefixed with ``step`` (the scale nodes' exchange)."""
    return _STAMP.pack(step) + payload


def parse_stamped(payload: bytes) -> Tuple[int, memoryview]:
    """Return (step, payload view) of :func:`stamped` bytes (no copy)."""
    return _STAMP.unpack_from(payload, 0)[0], memoryview(payload)[_STAMP.size:]


# --- coordinator -> scale nodes ---
def pack_step_input(inp: StepInput) -> bytes:
    """Return the byte form of a step input."""
    faults = (json.dumps([e.as_dict() for e in inp.faults]).encode('utf-8') if inp.faults
              else b'')
    return b''.join((_STEP_HEADER.pack(inp.step, inp.time_ns, inp.belt_speed.size,
                                       inp.actuator_position.size),
                     inp.belt_speed.astype('<f8').tobytes(),
                     inp.actuator_position.astype('<f8').tobytes(),
                     _U32.pack(len(faults)), faults))


def unpack_step_input(data: bytes) -> StepInput:
    """Rebuild a :class:`StepInput` from :func:`pack_step_input` bytes (the same float64s)."""
    step, time_ns, nb, na = _STEP_HEADER.unpack_from(data, 0)
    off = _STEP_HEADER.size
    belts = np.frombuffer(data, '<f8', nb, off).astype(np.float64)
    actuators = np.frombuffer(data, '<f8', na, off + 8 * nb).astype(np.float64)
    off += 8 * (nb + na)
    faults: tuple = ()
    if len(data) >= off + _U32.size:
        length, = _U32.unpack_from(data, off)
        if length:
            text = bytes(data[off + _U32.size:off + _U32.size + length]).decode('utf-8')
            faults = tuple(FaultEvent.from_dict(e) for e in json.loads(text))
    return StepInput(step, time_ns, belts, actuators, faults)


def step_payload(inp: StepInput) -> bytes:
    """Return the ``S`` payload of a step input."""
    return STEP + pack_step_input(inp)


def reset_payload(seed: int, cell_file: str) -> bytes:
    """Return the ``R`` payload: restart with ``seed`` and ``cell_file`` (empty: the current
    cell)."""
    return RESET + int(seed).to_bytes(8, 'little') + (cell_file or '').encode()


def parse_reset(body: bytes) -> Tuple[int, str]:
    """Return (seed, cell file) of a reset payload's body."""
    return int.from_bytes(body[:8], 'little'), bytes(body[8:]).decode()


def spawn_payload(type_index: int, x: np.ndarray, y: np.ndarray, yaw: np.ndarray) -> bytes:
    """Return the ``P`` payload: place parts of type ``type_index`` at the poses [m, rad]."""
    return (SPAWN + int(type_index).to_bytes(2, 'little')
            + np.ascontiguousarray(np.stack([x, y, yaw]), '<f8').tobytes())


def parse_spawn(body: bytes) -> Tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """Return (type index, x, y, yaw) of a spawn payload's body (arrays of their own)."""
    type_index = int.from_bytes(body[:2], 'little')
    poses = np.frombuffer(body[2:], '<f8').reshape(3, -1)
    return type_index, poses[0].copy(), poses[1].copy(), poses[2].copy()


def spawn_reply(ids: np.ndarray) -> bytes:
    """Return the micro node's reply to a spawn that placed parts ``ids``."""
    return b'I' + np.asarray(ids, '<u4').tobytes()


def spawn_error(message: str) -> bytes:
    """Return the micro node's reply to a spawn that placed nothing."""
    return b'E' + message.encode()


def parse_spawn_reply(reply: bytes) -> np.ndarray:
    """Return the ids of a :func:`spawn_reply`.

    :raises ValueError: with the micro node's message for a :func:`spawn_error`.
    """
    if reply[:1] == b'E':
        raise ValueError(bytes(reply[1:]).decode())
    return np.frombuffer(reply[1:], '<u4')


def part_query_payload(part_id: int) -> bytes:
    """Return the ``Q`` payload: does the micro scale hold part ``part_id`` now?"""
    return PART_QUERY + int(part_id).to_bytes(4, 'little')


def parse_part_query(body: bytes) -> int:
    """Return the part id of a part query's body."""
    return int.from_bytes(bytes(body[:4]), 'little')


def part_reply(exists: bool) -> bytes:
    """Return the micro node's answer to a part query."""
    return b'Y' if exists else b'N'


_MEASURES = b'\x00M'  # never the start of counters (JSON)


def step_reply(counters: bytes, measures: bytes) -> bytes:
    """Return the reply of a step: the counters (or nothing), preceded by the scenario
    triggers' measures when the node takes them (:func:`encode_measures`)."""
    if not measures:
        return counters
    return _MEASURES + _U32.pack(len(measures)) + measures + counters


def split_step_reply(reply: bytes) -> Tuple[bytes, bytes]:
    """Return (counters, measures) of a :func:`step_reply`."""
    if reply[:2] != _MEASURES:
        return reply, b''
    n, = _U32.unpack_from(reply, 2)
    return reply[6 + n:], reply[6:6 + n]


_LOADS = b'\x00L'  # never the start of counters (JSON) or measures


def with_loads(loads: np.ndarray, reply: bytes) -> bytes:
    """Return the micro node's step ``reply`` preceded by the step's actuator loads [N]."""
    return _LOADS + _U32.pack(loads.size) + np.asarray(loads, '<f8').tobytes() + reply


def split_loads(reply: bytes) -> Tuple[bytes, Optional[np.ndarray]]:
    """Return (the rest, the actuator loads [N] or None) of a :func:`with_loads` reply."""
    if reply[:2] != _LOADS:
        return reply, None
    n, = _U32.unpack_from(reply, 2)
    return reply[6 + 8 * n:], np.frombuffer(reply, '<f8', n, 6).astype(np.float64)


def encode_measures(edge_count: np.ndarray, zone_parts: np.ndarray) -> bytes:
    """Return what a scale node measures for a scenario's triggers after a step: the reported
    edge count of every light barrier (micro node; none from the macro node) and its share of
    the parts in every zone [parts] (micro: bodies, macro: density)."""
    return b''.join((_U32.pack(len(edge_count)), np.asarray(edge_count, '<u4').tobytes(),
                     _U32.pack(len(zone_parts)), np.asarray(zone_parts, '<f8').tobytes()))


def decode_measures(data: bytes) -> Tuple[np.ndarray, np.ndarray]:
    """Return (edge counts, zone parts) of :func:`encode_measures` bytes."""
    n, = _U32.unpack_from(data, 0)
    edges = np.frombuffer(data, '<u4', n, 4).astype(np.uint32)
    m, = _U32.unpack_from(data, 4 + 4 * n)
    zones = np.frombuffer(data, '<f8', m, 8 + 4 * n).astype(np.float64)
    return edges, zones


def encode_counters(counters: Dict[str, float]) -> bytes:
    """Return a stage's part-balance counters as the reply bytes of a step."""
    return json.dumps(counters, sort_keys=True).encode()


def decode_counters(prefix: str, reply: bytes) -> Dict[str, float]:
    """Return the counters of :func:`encode_counters` bytes, keys prefixed ``prefix_``."""
    if not reply:
        return {}
    return {f'{prefix}_{k}': v for k, v in json.loads(reply).items()}


# --- micro state -> macro node ---
def encode_state(sim: MicroSim) -> bytes:
    """Return the micro state the hand-over reads (see the module docstring), as bytes."""
    s = sim.state
    n = s.n
    return b''.join((s.counters.tobytes(), sim.sink_count.tobytes(), sim.act_state.tobytes(),
                     sim.act_verts.tobytes(), s.ids[:n].tobytes(), s.part_type[:n].tobytes(),
                     np.ascontiguousarray(s.P[:, :n]).tobytes()))


def load_state(sim: MicroSim, data: bytes) -> None:
    """Overwrite ``sim``'s state with :func:`encode_state` bytes of a simulator of the same
    cell.

    :raises ValueError: if the byte count does not match the cell.
    """
    s = sim.state
    off = 0
    for arr in (s.counters, sim.sink_count, sim.act_state, sim.act_verts):
        flat = arr.reshape(-1)
        flat[:] = np.frombuffer(data, arr.dtype, flat.size, off)
        off += arr.nbytes
    n = s.n
    s.ids[:n] = np.frombuffer(data, np.uint32, n, off)
    off += 4 * n
    s.part_type[:n] = np.frombuffer(data, np.uint16, n, off)
    off += 2 * n
    s.P[:, :n] = np.frombuffer(data, np.float64, P_ROWS * n, off).reshape(P_ROWS, n)
    if off + 8 * P_ROWS * n != len(data):
        raise ValueError(f'micro state of {len(data)} bytes does not match this cell')


# --- hand-over edits -> micro node ---
def append_record(ids: np.ndarray, part_type: np.ndarray, P: np.ndarray) -> List[bytes]:
    """Return the chunks of one edit record: ``k`` parts appended (ids, types, ``P`` rows)."""
    k = ids.size
    return [_RECORD.pack(APPEND, k), ids.tobytes(), part_type.tobytes(),
            np.ascontiguousarray(P).tobytes()]


def remove_record(rows: np.ndarray) -> List[bytes]:
    """Return the chunks of one edit record: the rows removed by one ``remove(mask=...)``."""
    rows = np.asarray(rows, '<u4')
    return [_RECORD.pack(REMOVE, rows.size), rows.tobytes()]


def edit_log(records: int, chunks: Sequence[bytes]) -> bytes:
    """Return an edit log of ``records`` records from their chunks, in order."""
    return _U32.pack(records) + b''.join(chunks)


def apply_edits(sim: MicroSim, data: bytes, off: int = 0) -> int:
    """Replay an :func:`edit_log` on the real simulator; return the end offset.

    :raises ValueError: if an appended part's id is not the simulator's next id (the mirror
        and the real simulator diverged), or released parts do not fit.
    """
    (records,) = _U32.unpack_from(data, off)
    off += _U32.size
    s = sim.state
    for _ in range(records):
        kind, k = _RECORD.unpack_from(data, off)
        off += _RECORD.size
        if kind == APPEND:
            n = s.n
            if n + k > s.capacity:
                raise ValueError(f'{k} released parts do not fit ({n} of {s.capacity} used)')
            ids = np.frombuffer(data, np.uint32, k, off)
            if int(ids[0]) != int(s.counters[C_NEXT_ID]):
                raise ValueError(f'released part id {int(ids[0])} is not the next id '
                                 f'{int(s.counters[C_NEXT_ID])}: micro mirror diverged')
            s.ids[n:n + k] = ids
            off += 4 * k
            s.part_type[n:n + k] = np.frombuffer(data, np.uint16, k, off)
            off += 2 * k
            s.P[:, n:n + k] = np.frombuffer(data, np.float64, P_ROWS * k, off).reshape(P_ROWS, k)
            off += 8 * P_ROWS * k
            # what place() counts per part
            s.counters[C_N] += k
            s.counters[C_NEXT_ID] += k
            s.counters[C_ENTERED] += k
        elif kind == REMOVE:
            rows = np.frombuffer(data, '<u4', k, off)
            off += 4 * k
            mask = np.zeros(s.n, dtype=np.bool_)
            mask[rows] = True
            sim.remove(mask=mask)
        else:
            raise ValueError(f'unknown edit record {kind!r}')
    return off


# --- light barriers in macro zones -> micro node ---
def encode_barriers(barriers: Sequence, edges: Sequence[Tuple[int, bool, float]]) -> bytes:
    """Return the barrier part of a hand-over reply.

    :param barriers: objects with ``index``, ``blocked``, ``edge_count`` (one per barrier in a
        ``macro`` zone).
    :param edges: the step's edges (barrier index, blocked, time [s]).
    """
    b = np.zeros(len(barriers), _BARRIER)
    for k, barrier in enumerate(barriers):
        b[k] = (barrier.index, bool(barrier.blocked), int(barrier.edge_count))
    e = np.zeros(len(edges), _EDGE)
    for k, edge in enumerate(edges):
        e[k] = edge
    return b''.join((_U32.pack(b.size), b.tobytes(), _U32.pack(e.size), e.tobytes()))


def decode_barriers(data: bytes, off: int) -> Tuple[List[Tuple[int, bool, int]],
                                                    List[Tuple[int, bool, float]], int]:
    """Return (barriers as (index, blocked, edge_count), edges as (index, blocked, time [s]),
    end offset) of the :func:`encode_barriers` part of a reply at ``off``."""
    (nb,) = _U32.unpack_from(data, off)
    off += _U32.size
    b = np.frombuffer(data, _BARRIER, nb, off)
    off += _BARRIER.itemsize * nb
    barriers = [(int(i), bool(k), int(c))
                for i, k, c in zip(b['index'], b['blocked'], b['edge_count'])]
    (ne,) = _U32.unpack_from(data, off)
    off += _U32.size
    e = np.frombuffer(data, _EDGE, ne, off)
    off += _EDGE.itemsize * ne
    edges = [(int(i), bool(k), float(t)) for i, k, t in zip(e['index'], e['blocked'], e['time'])]
    return barriers, edges, off
