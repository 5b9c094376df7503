"""The scale hand-over across processes: a micro mirror, and the bytes both ways (no ROS imports).

Composed, :class:`~conveyor_twin.coupling.scale.ScaleCoupling` works on the real micro simulator
after the micro and macro steps. Split over processes (micro and macro nodes apart), the
coupling runs in the macro process on a :class:`MirrorSim`: a micro simulator of the same cell
whose dynamic state is overwritten every step from the micro state bytes the micro process
sends after its micro step, and which logs every edit the coupling makes to it (parts appended
by releases, removal masks of captures) in order. The macro process sends that log back with the
light-barrier values of ``macro`` zones (:meth:`MacroSide.couple`); the micro process replays
it on its real simulator (:meth:`MicroSide.apply`): the same removals, the same appended rows
(exactly what :func:`conveyor_twin.micro.sources.place` wrote in the mirror: id, type, the nine
float rows and the counters ``n``, ``next_id``, ``entered``), so both layouts hold the same bytes.

The bytes both ways are the protocol's (:mod:`conveyor_twin.split.protocol`: the micro state,
the edit log and the barrier values).
"""

from typing import List, Optional, Sequence

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coupling.scale import ScaleCoupling
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coupling.zone_barriers import RemoteBarriers
from conveyor_twin.micro.sim import MicroSim
from conveyor_twin.micro.state import PartsView
from conveyor_twin.split import protocol


def has_coupling(cell: Cell) -> bool:
    """Return True if ``cell`` has zones simulated macro (``macro`` or ``auto``): the scales
    then hand parts over every step."""
    return any(z.policy in ('macro', 'auto') for z in cell.zones)


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
        """Take :func:`~conveyor_twin.split.protocol.encode_state` bytes of the real simulator;
        start a new edit log."""
        protocol.load_state(self, data)
        self._mark = self.n
        self._log = []
        self._records = 0

    def _log_appended(self) -> None:
        """Log the rows appended since the last mark (released parts)."""
        s, a, b = self.state, self._mark, self.n
        if b > a:
            self._log += protocol.append_record(s.ids[a:b], s.part_type[a:b], s.P[:, a:b])
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
        self._log += protocol.remove_record(rows)
        self._records += 1
        self._mark = self.n
        return view

    def take_edits(self) -> bytes:
        """Return the edit log since :meth:`load` (or the last call) and start a new one."""
        self._log_appended()
        out = protocol.edit_log(self._records, self._log)
        self._log = []
        self._records = 0
        return out


# --- the two halves ---
class MicroSide:
    """The micro process's half: its :class:`MicroStage` sends state, applies replies.

    :param stage: the real micro stage.
    :param barriers: the holder the micro stage was built with (``macro_barriers``): it takes
        the barrier values of every reply.
    """

    def __init__(self, stage, barriers: RemoteBarriers) -> None:
        self.stage = stage
        self.barriers = barriers

    def reset(self) -> None:
        """Forget the barrier values (after the stage's reset)."""
        self.barriers.clear()

    def state_bytes(self) -> bytes:
        """Return the micro state for the macro process (after the micro step)."""
        return protocol.encode_state(self.stage.sim)

    def apply(self, reply: bytes) -> None:
        """Replay a :meth:`MacroSide.couple` reply on the real simulator."""
        off = protocol.apply_edits(self.stage.sim, reply)
        barriers, edges, _ = protocol.decode_barriers(reply, off)
        self.barriers.load(barriers, edges)


class MirrorStage:
    """Stands in for the micro stage of the coupling in the macro process (its ``sim`` is a
    :class:`MirrorSim`)."""

    def __init__(self, cell: Cell, seed: int) -> None:
        self.reset(cell, seed)

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart with an empty mirror."""
        self.cell = cell
        self.sim = MirrorSim(cell, seed=seed)


class MacroSide:
    """The macro process's half: the coupling of ``macro_stage`` and a micro mirror.

    :param macro_stage: the macro stage.
    :param check: the ledger check of :class:`ScaleCoupling` (None: from the environment).
    """

    def __init__(self, macro_stage, cell: Cell, seed: int, *,
                 check: Optional[bool] = None) -> None:
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
        return sim.take_edits() + self._barrier_bytes()

    def _barrier_bytes(self) -> bytes:
        return protocol.encode_barriers(self.coupling.barriers, self.coupling.macro_edges)

    def force_tiles(self, zone: str, macro: np.ndarray, state: bytes) -> bytes:
        """Set an ``auto`` zone's tiles now (:meth:`ScaleCoupling.force_tiles`) on the micro
        ``state``; return the reply for :meth:`MicroSide.apply`."""
        sim = self.mirror.sim
        sim.load(state)
        self.coupling.force_tiles(zone, macro)
        return sim.take_edits() + self._barrier_bytes()
