"""One cell of a plant: its twin, the exits and entries of its links, plant-wide ids.

:class:`PlantCellCore` steps a composed twin (:func:`~conveyor_twin.coord.assembly.build_twin`)
and, around each step ``s``:

1. before the physics, every entry (links in plant order) inserts the parts due at ``s``
   (left upstream at ``s - delay`` or earlier), in order, each where it does not overlap
   anything; the first that does not fit waits with all behind it;
2. the twin steps;
3. after the physics, every exit takes the parts whose centre is in its rectangle (ids
   ascending), as many as the link has room for; they leave the cell as hand-overs (the
   micro ledger's ``handed_over``) and travel with their pose relative to the link.

Ids: cell ``k`` numbers its parts from ``k * 2**24 + 1`` (:data:`~conveyor_twin.plant.model.
ID_RANGE`), so ids are unique plant-wide at every instant; a part entering from a link gets
the next id of its new cell, and the link carries the id it had upstream and its ``origin``
(its id where it entered the plant), which a cell keeps for the parts it received.
"""

import hashlib
import math
from typing import Dict, List, Optional, Tuple

import numpy as np

from conveyor_twin.coord.assembly import AssembledTwin, build_twin
from conveyor_twin.micro.state import C_NEXT_ID, C_REGION_LEFT, C_REMOVED, PT_BRAD
from conveyor_twin.plant.geometry import entry_pose, mark_inside, to_link
from conveyor_twin.plant.ledger import CellReport
from conveyor_twin.plant.link import LinkEntry, LinkExit, Transit
from conveyor_twin.plant.model import ID_RANGE, Plant, PlantCell
from conveyor_twin.plant.sync import horizon


class PlantCellCore:
    """A cell of a plant with the ends of its links.

    :param plant: the validated plant. :param name: the cell's name in it.
    :param run: id of this run of the cell (sent to its neighbours: a restarted cell process
        takes another, so upstream cells send again what it never inserted and downstream
        cells follow its new numbering of parts and steps).
    :param check_balance: check the cell's part ledger every step (see ``build_twin``).
    :param twin: the composed twin of the cell to step (one a ROS layer built, with its
        streams); None: build one.
    :param lockstep: step as one with the neighbours: never more than one step ahead of any.
    """

    def __init__(self, plant: Plant, name: str, *, run: int = 0,
                 check_balance: Optional[bool] = None, twin: Optional[AssembledTwin] = None,
                 lockstep: bool = False) -> None:
        self.plant = plant
        self.spec: PlantCell = plant.cell(name)
        self.name = name
        #: Id of this run of the cell.
        self.run = run
        self.lockstep = lockstep
        self.twin: AssembledTwin = twin if twin is not None else build_twin(
            self.spec.cell, seed=self.spec.seed, check_balance=check_balance)
        sim = self.twin.micro.sim
        sim.state.counters[C_NEXT_ID] = self.spec.index * ID_RANGE + 1
        self.exits: List[LinkExit] = [LinkExit(k, run) for k in plant.links_from(name)]
        self.entries: List[LinkEntry] = [LinkEntry(k, run) for k in plant.links_to(name)]
        self._radius = sim.pt[:, PT_BRAD].copy()  # bounding radius per part type [m]
        # the exits' rectangles as mark_inside takes them, and its mask
        self._exit_rects = [(f.x, f.y, math.cos(f.yaw), math.sin(f.yaw), f.x0, f.x1,
                             f.half_width) for f in (x.link.exit for x in self.exits)]
        self._mark = np.zeros(sim.state.P.shape[1], dtype=np.bool_)
        self._origin: Dict[int, int] = {}
        self._digest = hashlib.sha256()
        #: Parts due and waiting at the entries after the last step, per entry.
        self.waiting = [0] * len(self.entries)
        #: The run has completed its last step (:meth:`finish`).
        self.finished = False

    @property
    def step_index(self) -> int:
        """Steps completed."""
        return self.twin.twin.step_index

    def horizon(self) -> int:
        """The last step this cell may compute now (:func:`~conveyor_twin.plant.sync.horizon`)."""
        limit = horizon(self.entries, self.exits)
        if self.lockstep:
            for end in self.entries:
                limit = min(limit, end.peer_through + 1)
            for end in self.exits:
                if not end.peer_final:   # a finished entry cell steps no more
                    limit = min(limit, end.peer_through + 1)
        return limit

    def may_step(self) -> bool:
        """True if the next step may be computed with what the neighbours reported."""
        return self.step_index + 1 <= self.horizon()

    def finish(self) -> None:
        """Mark the run complete: the entries' next batches say ``final`` (nothing more will be
        inserted), which is what the upstream cells wait for before their last report."""
        self.finished = True
        for e in self.entries:
            e.finished = True

    def settled(self) -> bool:
        """True once every exit heard its entry cell's final batch: the counts of this cell's
        links then agree with the downstream cells' last counts."""
        return all(x.peer_final for x in self.exits)

    def step(self) -> None:
        """Compute the next step: entries, physics, exits (see the module docstring).

        :raises RuntimeError: if the neighbours have not reported far enough, or the run
            is finished.
        """
        if self.finished:
            raise RuntimeError(f'cell {self.name!r} finished its run at step {self.step_index}')
        s = self.step_index + 1
        if s > self.horizon():
            raise RuntimeError(f'cell {self.name!r} may not compute step {s} yet '
                               f'(neighbours allow up to {self.horizon()})')
        sim = self.twin.micro.sim
        for k, entry in enumerate(self.entries):
            if entry.queue:
                link = entry.link

                def place(part: Transit, link=link) -> int:
                    t = link.type_map[part.part_type]
                    x, y, yaw, vx, vy = entry_pose(link.entry, float(self._radius[t]), part.y,
                                                   part.yaw, part.vx, part.vy)
                    new = sim.place_one(t, x, y, yaw, vx, vy, part.wz)
                    if new:
                        self._origin[new] = part.origin
                    return new
                self.waiting[k] = entry.insert(s, place)[1]
            else:
                self.waiting[k] = 0
        self.twin.step(1)
        for x, rect in zip(self.exits, self._exit_rects):
            self._take(x, rect, s)
        for end in self.entries:
            end.through = s
        for end in self.exits:
            end.through = s

    def _take(self, x: LinkExit, rect: Tuple[float, ...], s: int) -> None:
        """Move the parts in exit ``x``'s rectangle (at most its room) into its link."""
        sim = self.twin.micro.sim
        n = sim.n
        if not n:
            return
        st = sim.state
        if not mark_inside(*rect, st.P[0], st.P[1], n, x.room(s), self._mark):
            return
        mask = self._mark[:n]
        view = sim.remove(mask=mask)
        k = len(view.id)
        st.counters[C_REMOVED] -= k      # handed over to the link, not removed
        st.counters[C_REGION_LEFT] += k
        lx, ly, lyaw, lvx, lvy = to_link(x.link.exit, view.x, view.y, view.yaw, view.vx,
                                         view.vy)
        for i in range(k):
            pid = int(view.id[i])
            part = Transit(x.sent, s, pid, self._origin.pop(pid, pid), int(view.part_type[i]),
                           float(lx[i]), float(ly[i]), float(lyaw[i]), float(lvx[i]),
                           float(lvy[i]), float(view.wz[i]))
            self._digest.update(repr(part).encode())
            x.add(part)

    def counts(self) -> Dict[str, float]:
        """Return the cell's part ledger [parts]: ``entered`` (sources and spawns, not link
        arrivals), ``in_cell``, ``left`` (through sinks), ``vanished``, ``sent`` (into links),
        ``inserted`` (from links)."""
        coupling = self.twin.coupling
        if coupling is not None and coupling.enabled:
            led = coupling.ledger()
            total = led['entered']
            in_cell = led['micro'] + led['macro'] + led['pending']
            left, vanished = led['left'], led['vanished']
        else:
            c = self.twin.micro.sim.counters()
            total, in_cell = float(c['entered']), float(c['in_flight'])
            left, vanished = float(c['left']), float(c['vanished'])
        inserted = float(sum(e.inserted for e in self.entries))
        return {'entered': total - inserted, 'in_cell': in_cell, 'left': left,
                'vanished': vanished, 'sent': float(sum(x.sent for x in self.exits)),
                'inserted': inserted}

    def report(self, *, done: bool = False, with_hash: bool = False) -> CellReport:
        """Return the cell's report now (what ``progress`` carries; ``with_hash``: with its
        state digest)."""
        c = self.counts()
        return CellReport(
            cell=self.name, run=self.run, step=self.step_index, done=done,
            entered=c['entered'], in_cell=c['in_cell'], left=c['left'], vanished=c['vanished'],
            exit_link=[x.link.name for x in self.exits], exit_sent=[x.sent for x in self.exits],
            exit_accepted=[x.accepted for x in self.exits],
            exit_resent=[x.resent for x in self.exits],
            entry_link=[e.link.name for e in self.entries],
            entry_inserted=[e.inserted for e in self.entries],
            entry_waiting=list(self.waiting),
            entry_earlier=[e.earlier for e in self.entries],
            entry_dropped=[e.dropped for e in self.entries],
            state_hash=self.state_hash() if with_hash else '')

    def state_hash(self) -> str:
        """Return a SHA-256 digest of the cell's micro state and of every part it sent."""
        h = self._digest.copy()
        h.update(self.twin.micro.sim.state_bytes())
        return h.hexdigest()
