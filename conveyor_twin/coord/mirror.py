"""The scale hand-over across processes: a micro mirror, and the bytes both ways (no ROS imports).

Composed, :class:`~conveyor_twin.coord.scale.ScaleCoupling` works on the real micro simulator
after the micro and macro steps. Split over processes (micro and macro nodes apart), the
coupling runs in the macro process on a :class:`MirrorSim`: a micro simulator of the same cell
whose dynamic state is overwritten every step from :func:`encode_state` bytes the micro process
sends after its micro step, and which logs every edit the coupling makes to it (parts appended
by releases, removal masks of captures) in order. The macro process sends that log back with the
light-barrier values of ``macro`` zones (:meth:`MacroSide.couple`); the micro process replays
it on its real simulator (:meth:`MicroSide.apply`): the same removals, the same appended rows
(exactly what :func:`conveyor_twin.micro.sources.place` wrote in the mirror: id, type, the nine
float rows and the counters ``n``, ``next_id``, ``entered``), so both layouts hold the same bytes.

State bytes (little-endian): ``counters`` (int64 x C_COUNTERS), ``sink_count`` (int64 per
sink), ``act_state``, ``act_verts`` (float64, fixed shapes), then ``ids[:n]`` (uint32),
``part_type[:n]`` (uint16), ``P[:, :n]`` (float64, rows x n; ``n = counters[C_N]``).

Reply bytes: ``uint32`` record count, then records ``b'A' uint32 k`` + ids, types, ``P`` rows
of ``k`` appended parts, or ``b'R' uint32 k`` + ``k`` uint32 row indices removed (one
``remove(mask=...)``); then ``uint32`` barrier count + ``(int64 index, uint8 blocked,
int64 edge_count)`` each; then ``uint32`` edge count + ``(int64 index, uint8 blocked,
float64 time [s])`` each (the step's edges of barriers in macro zones).
"""

import struct
from typing import List, NamedTuple, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.micro.sim import MicroSim
from conveyor_twin.micro.state import C_ENTERED, C_N, C_NEXT_ID, P_ROWS, PartsView

_U32 = struct.Struct('<I')
_RECORD = struct.Struct('<cI')
_BARRIER = np.dtype([('index', '<i8'), ('blocked', 'u1'), ('edge_count', '<i8')])
_EDGE = np.dtype([('index', '<i8'), ('blocked', 'u1'), ('time', '<f8')])
APPEND = b'A'
REMOVE = b'R'


def has_coupling(cell: Cell) -> bool:
    """Return True if ``cell`` has zones simulated macro (``macro`` or ``auto``): the scales
    then hand parts over every step."""
    return any(z.policy in ('macro', 'auto') for z in cell.zones)


# --- micro state -> macro process ---
def encode_state(sim: MicroSim) -> bytes:
    """Return the micro state the coupling reads (see the module docstring), as bytes."""
    s = sim.state
    n = s.n
    return b''.join((s.counters.tobytes(), sim.sink_count.tobytes(), sim.act_state.tobytes(),
                     sim.act_verts.tobytes(), s.ids[:n].tobytes(), s.part_type[:n].tobytes(),
                     np.ascontiguousarray(s.P[:, :n]).tobytes()))


def load_state(sim: MicroSim, data: bytes) -> None:
    """Overwrite ``sim``'s state with :func:`encode_state` bytes of a simulator of the same
    cell."""
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


class MirrorSim(MicroSim):
    """A micro simulator whose state comes from another process and whose edits are logged.

    Never stepped: :meth:`load` overwrites the state, the coupling edits it through
    :meth:`remove` and (in compiled code) ``place`` at row ``n``, and :meth:`take_edits`
    returns the log in order.
    """

    def __init__(self, cell: Cell, *, seed: int) -> None:
        super().__init__(cell, seed=seed)
        self._mark = 0
        self._log: List[bytes] = []
        self._records = 0

    def load(self, data: bytes) -> None:
        """Take :func:`encode_state` bytes of the real simulator; start a new edit log."""
        load_state(self, data)
        self._mark = self.n
        self._log = []
        self._records = 0

    def _log_appended(self) -> None:
        """Log the rows appended since the last mark (released parts)."""
        s, a, b = self.state, self._mark, self.n
        if b > a:
            self._log += [_RECORD.pack(APPEND, b - a), s.ids[a:b].tobytes(),
                          s.part_type[a:b].tobytes(), np.ascontiguousarray(s.P[:, a:b]).tobytes()]
            self._records += 1
        self._mark = b

    def remove(self, ids: Optional[Sequence[int]] = None, *,
               mask: Optional[np.ndarray] = None) -> PartsView:
        """Log the appended rows and the removal, then remove (as :meth:`MicroSim.remove`)."""
        n = self.n
        if mask is None:
            mask = np.isin(self.state.ids[:n], np.asarray(ids if ids is not None else [],
                                                          dtype=np.uint32))
        mask = np.asarray(mask, dtype=np.bool_)
        self._log_appended()
        rows = np.flatnonzero(mask).astype('<u4') if mask.shape == (n,) else None
        view = super().remove(mask=mask)  # raises on a wrong shape
        self._log += [_RECORD.pack(REMOVE, rows.size), rows.tobytes()]
        self._records += 1
        self._mark = self.n
        return view

    def take_edits(self) -> bytes:
        """Return the edit log since :meth:`load` (or the last call) and start a new one."""
        self._log_appended()
        out = _U32.pack(self._records) + b''.join(self._log)
        self._log = []
        self._records = 0
        return out


def apply_edits(sim: MicroSim, data: bytes, off: int = 0) -> int:
    """Replay :meth:`MirrorSim.take_edits` bytes on the real simulator; return the end offset.

    :raises ValueError: if an appended part's id is not the simulator's next id (the mirror
        and the real simulator diverged).
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


# --- light barriers in macro zones -> micro process ---
class BarrierValue(NamedTuple):
    """One light barrier in a macro zone as the micro stage publishes it."""

    index: int
    blocked: bool
    edge_count: int


class RemoteCoupling:
    """What :class:`~conveyor_twin.coord.stages.MicroStage` reads of its ``coupling`` when the
    coupling runs in another process: the barriers of macro zones and the step's edges."""

    def __init__(self) -> None:
        self.barriers: List[BarrierValue] = []
        self.macro_edges: List[Tuple[int, bool, float]] = []
        self.macro_barrier_index = np.zeros(0, dtype=np.int64)

    def decode(self, data: bytes, off: int) -> int:
        """Take the barrier part of a reply at ``off``; return the end offset."""
        (nb,) = _U32.unpack_from(data, off)
        off += _U32.size
        b = np.frombuffer(data, _BARRIER, nb, off)
        off += _BARRIER.itemsize * nb
        self.barriers = [BarrierValue(int(i), bool(k), int(c))
                         for i, k, c in zip(b['index'], b['blocked'], b['edge_count'])]
        self.macro_barrier_index = b['index'].astype(np.int64)
        (ne,) = _U32.unpack_from(data, off)
        off += _U32.size
        e = np.frombuffer(data, _EDGE, ne, off)
        off += _EDGE.itemsize * ne
        self.macro_edges = [(int(i), bool(k), float(t))
                            for i, k, t in zip(e['index'], e['blocked'], e['time'])]
        return off


def encode_barriers(coupling) -> bytes:
    """Return the barrier part of a reply: a :class:`ScaleCoupling`'s barriers and edges."""
    b = np.zeros(len(coupling.barriers), _BARRIER)
    for k, barrier in enumerate(coupling.barriers):
        b[k] = (barrier.index, bool(barrier.blocked), int(barrier.edge_count))
    e = np.zeros(len(coupling.macro_edges), _EDGE)
    for k, edge in enumerate(coupling.macro_edges):
        e[k] = edge
    return b''.join((_U32.pack(b.size), b.tobytes(), _U32.pack(e.size), e.tobytes()))


# --- the two halves ---
class MicroSide:
    """The micro process's half: its :class:`MicroStage` sends state, applies replies.

    :param stage: the real micro stage (its ``coupling`` becomes a :class:`RemoteCoupling`).
    """

    def __init__(self, stage) -> None:
        self.stage = stage
        self.remote = RemoteCoupling()
        self.stage.coupling = self.remote

    def reset(self) -> None:
        """Re-attach to the stage after its reset (which drops its coupling)."""
        self.remote = RemoteCoupling()
        self.stage.coupling = self.remote

    def state_bytes(self) -> bytes:
        """Return the micro state for the macro process (after the micro step)."""
        return encode_state(self.stage.sim)

    def apply(self, reply: bytes) -> None:
        """Replay a :meth:`MacroSide.couple` reply on the real simulator."""
        off = apply_edits(self.stage.sim, reply)
        self.remote.decode(reply, off)


class MirrorStage:
    """Stands in for the micro stage of the coupling in the macro process (its ``sim`` is a
    :class:`MirrorSim`)."""

    def __init__(self, cell: Cell, seed: int) -> None:
        self.coupling = None
        self.reset(cell, seed)

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart with an empty mirror."""
        self.cell = cell
        self.sim = MirrorSim(cell, seed=seed)


class MacroSide:
    """The macro process's half: the coupling of ``macro_stage`` and a micro mirror.

    :param macro_stage: the macro stage (its ``coupling`` is set, so its counters carry the
        ledger).
    :param check: the ledger check of :class:`ScaleCoupling` (None: from the environment).
    """

    def __init__(self, macro_stage, cell: Cell, seed: int, *,
                 check: Optional[bool] = None) -> None:
        from conveyor_twin.coord.scale import ScaleCoupling
        self.macro_stage = macro_stage
        self.mirror = MirrorStage(cell, seed)
        self.coupling = ScaleCoupling(self.mirror, macro_stage, check=check)

    def reset(self, cell: Cell, seed: int) -> None:
        """Rebind after the macro stage's reset."""
        self.mirror.reset(cell, seed)
        self.coupling.reset(cell, seed)

    def couple(self, inp: StepInput, state: bytes) -> bytes:
        """Hand parts and mass over after the step ``inp`` of both scales; return the reply.

        :param state: the micro process's :meth:`MicroSide.state_bytes` after its step.
        """
        sim = self.mirror.sim
        sim.load(state)
        self.coupling.advance(inp)
        return sim.take_edits() + encode_barriers(self.coupling)

    def force_tiles(self, zone: str, macro: np.ndarray, state: bytes) -> bytes:
        """Set an ``auto`` zone's tiles now (:meth:`ScaleCoupling.force_tiles`) on the micro
        ``state``; return the reply for :meth:`MicroSide.apply`."""
        sim = self.mirror.sim
        sim.load(state)
        self.coupling.force_tiles(zone, macro)
        return sim.take_edits() + encode_barriers(self.coupling)
