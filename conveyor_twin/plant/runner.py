"""All cells of a plant stepped in one process (no ROS imports).

:class:`PlantRunner` builds a :class:`~conveyor_twin.plant.cell.PlantCellCore` per cell and
moves the links' batches between them directly, the same batches the cells exchange over ROS
when each runs in its own process. :meth:`PlantRunner.step` steps the plant as one (every cell
one step: lockstep); :meth:`PlantRunner.run_to` lets every cell run as far as the conservative
rule allows (:mod:`conveyor_twin.plant.sync`) before the batches move: cells run up to the link
delay apart. Both give the same bits, and so does one process per cell.
"""

from typing import Dict, List, Mapping, Optional

from conveyor_twin.coord.assembly import AssembledTwin
from conveyor_twin.plant.cell import PlantCellCore
from conveyor_twin.plant.ledger import LinkCounts, PlantLedger
from conveyor_twin.plant.link import LinkEntry, LinkExit
from conveyor_twin.plant.model import Plant


class PlantRunner:
    """The plant in one process.

    :param plant: the validated plant.
    :param check_balance: check each cell's part ledger every step.
    :param twins: the composed twins of some cells, by name (a ROS layer built them, with
        their streams); the others are built here.
    """

    def __init__(self, plant: Plant, *, check_balance: Optional[bool] = None,
                 twins: Optional[Mapping[str, AssembledTwin]] = None) -> None:
        self.plant = plant
        twins = twins or {}
        self.cells: List[PlantCellCore] = [PlantCellCore(plant, c.name,
                                                         check_balance=check_balance,
                                                         twin=twins.get(c.name))
                                           for c in plant.cells]
        self.by_name: Dict[str, PlantCellCore] = {c.name: c for c in self.cells}
        self._exits: Dict[str, LinkExit] = {}
        self._entries: Dict[str, LinkEntry] = {}
        for c in self.cells:
            for x in c.exits:
                self._exits[x.link.name] = x
            for e in c.entries:
                self._entries[e.link.name] = e

    @property
    def step_index(self) -> int:
        """Steps every cell has completed (the slowest cell's)."""
        return min(c.step_index for c in self.cells)

    def exchange(self) -> None:
        """Hand every link's batches to the other end (departures, then acceptances)."""
        for name, x in self._exits.items():
            self._entries[name].receive(x.batch())
        for name, e in self._entries.items():
            self._exits[name].receive(e.batch())

    def step(self, n: int = 1) -> None:
        """Step the plant as one, ``n`` times: every cell one step, in plant order."""
        for _ in range(n):
            for c in self.cells:
                c.step()
                self.exchange()

    def run_to(self, end: int) -> None:
        """Run every cell to step ``end``, each as far ahead as the rule allows between two
        exchanges of batches."""
        while self.step_index < end:
            moved = False
            for c in self.cells:
                limit = min(end, c.horizon())
                while c.step_index < limit:
                    c.step()
                    moved = True
                self.exchange()
            if not moved:
                raise RuntimeError('no cell may step: the plant is deadlocked')

    def ledger(self) -> PlantLedger:
        """Return the plant-wide ledger now."""
        links = {}
        for name, x in self._exits.items():
            e = self._entries[name]
            owner = self.by_name[e.link.target.cell]
            waiting = owner.waiting[owner.entries.index(e)]
            links[name] = LinkCounts(sent=x.sent, inserted=e.inserted, waiting=waiting,
                                     resent=x.resent)
        return PlantLedger({c.name: c.counts() for c in self.cells}, links)

    def state_hashes(self) -> Dict[str, str]:
        """Return every cell's state digest (:meth:`PlantCellCore.state_hash`)."""
        return {c.name: c.state_hash() for c in self.cells}
