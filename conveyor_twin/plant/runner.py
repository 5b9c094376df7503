"""All cells of a plant stepped in one process (no ROS imports).

:class:`PlantRunner` builds a :class:`~conveyor_twin.plant.cell.PlantCellCore` per cell and
moves the links' batches between them directly, the same batches the cells exchange over ROS
when each runs in its own process. :meth:`PlantRunner.step` steps the plant as one (every cell
one step: lockstep); :meth:`PlantRunner.run_to` lets every cell run as far as the conservative
rule allows (:mod:`conveyor_twin.plant.sync`) before the batches move: cells run up to the link
delay apart. Both give the same bits, and so does one process per cell.
:meth:`PlantRunner.restart` replaces a cell by a new run of it, as a killed and restarted
cell process is (its state and what it had not exchanged are gone).
"""

from typing import Dict, List, Mapping, Optional

from conveyor_twin.coord.assembly import AssembledTwin
from conveyor_twin.plant.cell import PlantCellCore
from conveyor_twin.plant.ledger import CellReport, PlantLedger, ledger_of
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
        self._check_balance = check_balance
        #: The last report of every cell run that ended (:meth:`restart`).
        self.ended: List[CellReport] = []
        self._index()

    def _index(self) -> None:
        self.by_name: Dict[str, PlantCellCore] = {c.name: c for c in self.cells}
        self._exits: Dict[str, LinkExit] = {}
        self._entries: Dict[str, LinkEntry] = {}
        for c in self.cells:
            for x in c.exits:
                self._exits[x.link.name] = x
            for e in c.entries:
                self._entries[e.link.name] = e

    def restart(self, name: str, run: int) -> PlantCellCore:
        """Replace cell ``name`` by a new run ``run`` of it, from its initial state at step 0
        (a killed cell process started again): the batches move first and the old run
        reports (as a cell process does before it is killed), then the old run is gone with
        what it held. Return the new run.

        :raises ValueError: if ``run`` is the cell's current run id.
        """
        old = self.by_name[name]
        if run == old.run:
            raise ValueError(f'cell {name!r}: a restarted run needs another id than {run}')
        self.exchange()
        self.ended.append(old.report())
        new = PlantCellCore(self.plant, name, run=run, check_balance=self._check_balance)
        self.cells[self.cells.index(old)] = new
        self._index()
        return new

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

    def run_to(self, end: int, *, finish: bool = False) -> None:
        """Run every cell to step ``end``, each as far ahead as the rule allows between two
        exchanges of batches. ``finish``: a cell that reaches ``end`` finishes its run
        (:meth:`~conveyor_twin.plant.cell.PlantCellCore.finish`, as a cell process of a
        fixed-duration run does), and the last batches move.

        :raises RuntimeError: if no cell may step (a deadlock).
        """
        while self.step_index < end:
            moved = False
            for c in self.cells:
                limit = min(end, c.horizon())
                while c.step_index < limit:
                    c.step()
                    moved = True
                if finish and c.step_index >= end and not c.finished:
                    c.finish()
                    moved = True
                self.exchange()
            if not moved:
                steps = ', '.join(f'{c.name} {c.step_index} (may step to {c.horizon()})'
                                  for c in self.cells)
                raise RuntimeError(f'no cell may step: the plant is deadlocked at steps '
                                   f'{steps}')
        if finish:
            for c in self.cells:
                if not c.finished:
                    c.finish()
            self.exchange()

    def ledger(self) -> PlantLedger:
        """Return the plant-wide ledger now (every cell's report and the ended runs' last
        reports, :func:`~conveyor_twin.plant.ledger.ledger_of`; exact after an exchange)."""
        return ledger_of({c.name: c.report() for c in self.cells}, self.ended)

    def state_hashes(self) -> Dict[str, str]:
        """Return every cell's state digest (:meth:`PlantCellCore.state_hash`)."""
        return {c.name: c.state_hash() for c in self.cells}
