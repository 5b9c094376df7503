"""The parts of a frame, each built by the stage that owns the streams.

One producer per stage, each writing its streams into the step's
:class:`~conveyor_twin.output.frame.Frame` with the CDR encoders of
:mod:`conveyor_twin.wire.cdr` (bytes straight from the stages' numpy arrays, ~40 us for 1000
parts): :class:`CoordinatorOutput` (``/clock``, ``belt_states``, ``actuator_states``,
``diagnostics``, accepted commands), :class:`MicroOutput` (``parts``, ``light_barriers``,
``light_barrier_edges``) and :class:`MacroOutput` (``density``, one message per macro zone).
Composed, one frame gets all three; split, each process's frame gets the part of its stage.
"""

from typing import Callable, Optional, Protocol, Sequence

from conveyor_twin.contract import DIAGNOSTICS_PERIOD_STEPS
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.output.frame import Frame
from conveyor_twin.wire import cdr
from conveyor_twin.wire.fault_state import encode_fault_state, FaultEntry

#: Returns the ``DiagnosticArray`` CDR for a simulation time [ns].
DiagnosticsSource = Callable[[int], bytes]


class FrameProducer(Protocol):
    """Writes a stage's streams of the step just taken into the frame."""

    def fill(self, frame: Frame, inp: StepInput, commands: Sequence) -> None:
        """Set this stage's attributes of ``frame`` for the step of ``inp``."""


class CoordinatorOutput:
    """``/clock``, belt and actuator states, accepted commands and (when due) diagnostics.

    :param twin: the coordinator core (:class:`~conveyor_twin.coord.twin.Twin`).
    :param diagnostics: builds the diagnostics CDR every
        :data:`~conveyor_twin.contract.DIAGNOSTICS_PERIOD_STEPS` steps (None: no diagnostics,
        e.g. a re-simulation, whose step times would mean nothing).
    """

    def __init__(self, twin, *, diagnostics: Optional[DiagnosticsSource] = None) -> None:
        cell = twin.cell
        frame_id = cell.settings.frame_id
        self.twin = twin
        self.diagnostics = diagnostics
        self.frame_id = frame_id
        self._since: dict = {}  # fault id -> simulation time it became active [s]
        self._belts = cdr.BeltStatesEncoder(frame_id, [b.name for b in cell.belts])
        self._actuators = cdr.ActuatorStatesEncoder(frame_id, [a.name for a in cell.actuators])

    def fill(self, frame: Frame, inp: StepInput, commands: Sequence) -> None:
        """Encode the coordinator's streams of the step."""
        t = inp.time_ns
        actuation = self.twin.actuation
        frame.commands = commands
        frame.clock = cdr.encode_clock(t)
        frame.belt_states = self._belts.encode(t, actuation.belt_target, inp.belt_speed)
        frame.actuator_states = self._actuators.encode(t, actuation.actuator_target,
                                                       inp.actuator_position,
                                                       actuation.stall_flags,
                                                       actuation.actuator_load)
        if self.diagnostics is not None and inp.step % DIAGNOSTICS_PERIOD_STEPS == 0:
            frame.diagnostics = self.diagnostics(t)
        else:
            frame.diagnostics = None
        if inp.faults or inp.step == 1:
            frame.faults = self._fault_state(inp)
        else:
            frame.faults = None

    def _fault_state(self, inp: StepInput) -> bytes:
        """Return the ``FaultState`` CDR of the faults active from ``inp.step`` on."""
        book = self.twin.faults
        since = self._since
        if inp.step == 1:
            since.clear()
        for event in inp.faults:
            if event.action == 'inject':
                since[event.fault.id] = inp.time_ns * 1e-9
        active = [FaultEntry(f.id, f.kind, f.target, f.params, f.part_type, f.duration,
                             since.get(f.id, 0.0))
                  for f in sorted(book.active.values(), key=lambda f: f.id)]
        for fault_id in [i for i in since if i not in book.active]:
            del since[fault_id]
        return encode_fault_state(
            inp.time_ns, self.frame_id, active,
            [e.fault.id for e in inp.faults if e.action == 'inject'],
            [(e.fault.id, e.reason) for e in inp.faults if e.action == 'clear'],
            book.injected, book.rejected)


class MicroOutput:
    """Parts, light-barrier states and edges of a micro stage.

    :param stage: the :class:`~conveyor_twin.coord.stages.MicroStage`.
    """

    def __init__(self, stage) -> None:
        cell = stage.cell
        self.stage = stage
        self.frame_id = cell.settings.frame_id
        self.barrier_names = [b.name for b in cell.light_barriers]
        self._parts = cdr.PartStatesEncoder(self.frame_id, capacity=cell.micro.capacity)
        self._barriers = cdr.LightBarrierStatesEncoder(self.frame_id, self.barrier_names)

    def fill(self, frame: Frame, inp: StepInput, commands: Sequence) -> None:
        """Encode the micro streams of the step."""
        stage = self.stage
        t = inp.time_ns
        ids, part_type, x, y, yaw, vx, vy, wz = stage.parts()
        frame.parts = self._parts.encode(t, inp.step, ids, part_type, x, y, yaw, vx, vy, wz)
        frame.light_barriers = self._barriers.encode(t, inp.step, stage.barrier_blocked(),
                                                     stage.barrier_edge_count())
        barrier, rising, time_ns, part_id = stage.edges()
        if len(barrier):
            names, frame_id = self.barrier_names, self.frame_id
            frame.edges = [(int(time_ns[i]), cdr.encode_light_barrier_edge(
                int(time_ns[i]), frame_id, names[barrier[i]], bool(rising[i]), int(part_id[i])))
                for i in range(len(barrier))]
        else:
            frame.edges = ()


class MacroOutput:
    """The density grid of every macro zone of a macro stage.

    :param stage: the :class:`~conveyor_twin.coord.stages.MacroStage`.
    """

    def __init__(self, stage) -> None:
        frame_id = stage.cell.settings.frame_id
        self.stage = stage
        self._encoders = [cdr.DensityGridEncoder(frame_id, g.zone.name, g.origin_x, g.origin_y,
                                                 g.resolution, g.nx, g.ny)
                          for g in stage.grids]
        self._density = [b''] * len(self._encoders)

    def fill(self, frame: Frame, inp: StepInput, commands: Sequence) -> None:
        """Encode every macro zone's density of the step (one list, reused every step)."""
        density = self._density
        for i, grid in enumerate(self.stage.grids):
            density[i] = self._encoders[i].encode(inp.time_ns, inp.step, grid.density,
                                                  grid.total_parts())
        frame.density = density
