"""The coordinator core: owns simulation time, commands and actuation, and steps the scales.

Each step ``k`` (the state after it is stamped ``k * dt``):
1. the commands that arrived since step ``k - 1`` are drained, stamped ``k`` and applied to the
   belt and actuator targets (:class:`~conveyor_twin.coord.commands.CommandBook`); faults
   due at ``k`` are taken from the :class:`~conveyor_twin.faults.book.FaultBook`, and the
   command and drive faults filter the commands (:mod:`conveyor_twin.faults.actuation`);
2. belt speeds and actuator positions move one step toward their targets (drive faults
   applied);
3. one :class:`~conveyor_twin.coord.step_input.StepInput` is built, with the step's fault
   events, and every stage advances with it (split, the one stage is the scale processes,
   which get its bytes: :class:`~conveyor_twin.split.remote.RemoteStage`).
"""

import threading
import time
from typing import Callable, List, Optional, Protocol, Sequence

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.actuation import Actuation
from conveyor_twin.coord.clock import step_ns
from conveyor_twin.coord.commands import Command, CommandBook, CommandKind
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coord.timing import StepParts
from conveyor_twin.faults.actuation import ActuationFaults
from conveyor_twin.faults.book import FaultBook
from conveyor_twin.health import Health


class Stage(Protocol):
    """One scale's core behind a uniform per-step interface; its ``label`` (optional, else the
    class name) names it in the step's time per part (:class:`~.timing.StepParts`)."""

    def advance(self, inp: StepInput) -> None:
        """Advance one step with the coordinator's inputs."""

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart from the cell's initial state."""


class Twin:
    """Time, commands, actuation and the stages of one cell.

    :param cell: the validated cell.
    :param seed: random seed of the run (sources).
    :param stages: the stages stepped in this process, in order (the assembly,
        :func:`~conveyor_twin.coord.assembly.build_twin`, passes micro, macro and the scale
        coupling; the split layout's coordinator its remote stage).
    :param actuator_load: returns the load [N] on every actuator measured in the step just
        taken (the micro scale's), for the actuators' stalls; None: no stalls.
    """

    def __init__(self, cell: Cell, *, seed: int, stages: Sequence[Stage] = (),
                 actuator_load: Optional[Callable[[], Optional[np.ndarray]]] = None) -> None:
        self.lock = threading.RLock()
        self.stages: List[Stage] = list(stages)
        #: The slowest recent step's time per part (commands and actuation, each stage, the
        #: outputs: the actuators' load, step listeners and fault watchers) and its CPU time;
        #: in the coordinator's diagnostics.
        self.step_parts = StepParts(
            ['commands'] + [getattr(s, 'label', type(s).__name__) for s in self.stages]
            + ['outputs'])
        self._laps = [0] * (len(self.stages) + 2)
        self._actuator_load = actuator_load
        self.step_listeners: List[Callable[[StepInput, List[Command]], None]] = []
        self._last_commands: List[Command] = []
        self.commands = CommandBook(cell)
        #: Fault requests and the active faults (:mod:`conveyor_twin.faults`).
        self.faults = FaultBook(cell)
        #: Called after every step (after the listeners) with the step's input: scenario
        #: triggers that inject faults for the next step.
        self.fault_watchers: List[Callable[[StepInput], None]] = []
        #: Called after every reset (a scenario arms itself again).
        self.reset_listeners: List[Callable[[], None]] = []
        #: Failures of the background threads and processes that serve this twin
        #: (:mod:`conveyor_twin.health`): reported once, ERROR in diagnostics, non-zero exit.
        self.health = Health()
        self._load(cell, seed)

    def _load(self, cell: Cell, seed: int) -> None:
        self.cell = cell
        self.seed = seed
        self.dt_ns = step_ns(cell.settings.step)
        self.commands.clear()
        self.actuation = Actuation(cell)
        self.faults.load(cell)
        self.fault_actuation = ActuationFaults(cell, seed)
        self.step_index = 0

    def rebind(self, cell: Cell) -> None:
        """Use ``cell``'s names and ranges for command validation (after a reset)."""
        rejected = self.commands.rejected
        self.commands = CommandBook(cell)
        self.commands.rejected = rejected

    @property
    def time_ns(self) -> int:
        """Simulation time of the current state [ns]."""
        return self.step_index * self.dt_ns

    def reset(self, cell: Optional[Cell] = None, seed: Optional[int] = None) -> None:
        """Restart at step 0, optionally with another cell and/or seed; counters of rejected
        commands are kept for the process's diagnostics."""
        with self.lock:
            cell = cell or self.cell
            seed = self.seed if seed is None else seed
            if cell is not self.cell:
                self.rebind(cell)
            self._load(cell, seed)
            for stage in self.stages:
                stage.reset(cell, seed)
            for listener in self.reset_listeners:
                listener()

    def _apply(self, commands: List[Command]) -> None:
        for command in commands:
            if command.kind == CommandKind.BELT:
                self.actuation.set_belt_target(command.index, command.value)
            elif command.kind == CommandKind.ACTUATOR:
                self.actuation.set_actuator_target(command.index, command.value)

    def prepare(self) -> StepInput:
        """Drain and apply commands, move the actuation, and return the next step's input."""
        step = self.step_index + 1
        commands = self.commands.drain(step)
        events = self.faults.take(step)
        faults = self.fault_actuation
        if events or faults.busy:  # commands as received are recorded; faults act on them
            faults.apply(events, self.actuation)
            self._apply(faults.filter_commands(commands, step))
            self.actuation.advance()
            belt, position = faults.drive(self.actuation)
        else:
            self._apply(commands)
            self.actuation.advance()
            belt = self.actuation.belt_speed.copy()
            position = self.actuation.actuator_position.copy()
        inp = StepInput(step, step * self.dt_ns, belt, position, events)
        self._last_commands = commands
        return inp

    def step(self, n: int = 1) -> StepInput:
        """Advance ``n`` steps with the local stages; return the last step's input."""
        inp = None
        clock, cpu, laps = time.perf_counter_ns, time.thread_time_ns, self._laps
        with self.lock:
            for _ in range(n):
                cpu_start = cpu()
                start = clock()
                inp = self.prepare()
                lap = clock()
                laps[0] = lap - start
                for i, stage in enumerate(self.stages, 1):
                    stage.advance(inp)
                    start, lap = lap, clock()
                    laps[i] = lap - start
                if self._actuator_load is not None:
                    self.actuation.observe(self._actuator_load())
                self.step_index = inp.step
                for listener in self.step_listeners:
                    listener(inp, self._last_commands)
                for watcher in self.fault_watchers:
                    watcher(inp)
                laps[-1] = clock() - lap
                self.step_parts.add(laps, cpu() - cpu_start)
        return inp
