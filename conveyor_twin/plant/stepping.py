"""A plant's cells as :class:`~conveyor_twin.coord.runner.Runner` steps them (no ROS imports).

:class:`CellStepping` is one cell of a plant in a process of its own: the runner's steppable
(a step is :meth:`~conveyor_twin.plant.cell.PlantCellCore.step`) and its gate (the
conservative rule, :meth:`~conveyor_twin.plant.cell.PlantCellCore.may_step`). It sends the
links' batches every sync period (:func:`sync_period`) and whenever the cell has to wait for
its neighbours. :class:`PlantStepping` is every cell of a plant in one process
(:class:`~conveyor_twin.plant.runner.PlantRunner`).
"""

import threading
from typing import Callable

from conveyor_twin.coord.clock import step_ns
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import Health
from conveyor_twin.plant.cell import PlantCellCore
from conveyor_twin.plant.model import Plant
from conveyor_twin.plant.runner import PlantRunner


def sync_period(plant: Plant, mode: TimeMode) -> int:
    """Return the steps between two publications of a cell's batches: a quarter of the
    shortest link delay (so neighbours rarely wait), 1 in lockstep."""
    if mode is TimeMode.LOCKSTEP:
        return 1
    return max(1, plant.min_delay // 4)


class CellStepping:
    """One cell of a plant as a runner's steppable and gate.

    :param core: the cell. :param health: where the stepping thread reports its failure.
    :param period: steps between two calls of ``sync`` (:func:`sync_period`).
    :param sync: sends the links' batches; called on the stepping thread every ``period``
        steps (register :meth:`stepped` as a runner listener) and before every wait for the
        neighbours (:meth:`blocked`), never with :attr:`lock` held.

    Whoever hands the cell its neighbours' batches takes :attr:`lock` and then sets
    :attr:`wake`.
    """

    def __init__(self, core: PlantCellCore, health: Health, *, period: int,
                 sync: Callable[[], None]) -> None:
        self.core = core
        self.health = health
        #: Step period [ns].
        self.dt_ns = step_ns(core.plant.step)
        self.period = period
        #: Held while the rule is asked and the step runs, and while a batch is taken.
        self.lock = threading.Lock()
        #: Set when a neighbour's batch arrived (or to end a wait early).
        self.wake = threading.Event()
        self._sync = sync
        self._since = 0  # steps since the last sync

    def step(self, n: int = 1) -> None:
        """Compute the next ``n`` steps of the cell (the rule must allow them)."""
        if n == 1:  # the runner's every step
            self.core.step()
            return
        for _ in range(n):
            self.core.step()

    def may_step(self) -> bool:
        """True if the neighbours have reported far enough for the next step."""
        return self.core.may_step()

    def blocked(self) -> None:
        """Before a wait for the neighbours: send the batches (they may wait for this cell)."""
        self._since = 0
        self._sync()

    def stepped(self) -> None:
        """After a step: send the batches once every :attr:`period` steps."""
        self._since += 1
        if self._since >= self.period:
            self._since = 0
            self._sync()


class PlantStepping:
    """Every cell of a plant in one process as a runner's steppable.

    :param runner: the cells. :param health: where the stepping thread reports its failure.
    :param ahead: each cell runs as far ahead as the rule allows between two exchanges of
        batches (:meth:`~conveyor_twin.plant.runner.PlantRunner.run_to`; fast mode); False:
        the plant steps as one (:meth:`~conveyor_twin.plant.runner.PlantRunner.step`).
    """

    def __init__(self, runner: PlantRunner, health: Health, *, ahead: bool) -> None:
        self.runner = runner
        self.health = health
        self.ahead = ahead
        #: Step period [ns].
        self.dt_ns = step_ns(runner.plant.step)

    def step(self, n: int = 1) -> None:
        """Advance every cell ``n`` steps."""
        if self.ahead:
            self.runner.run_to(self.runner.step_index + n)
        else:
            self.runner.step(n)
