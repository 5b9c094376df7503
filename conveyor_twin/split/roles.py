"""What each process of the split layout is made of: one class per role (no ROS imports).

- :class:`CoordinatorRole`: the coordinator core (:class:`~conveyor_twin.coord.twin.Twin`)
  whose one stage is :class:`~conveyor_twin.split.remote.RemoteStage` (both scale processes);
- :class:`MicroRole`: the micro stage and, for cells with ``macro``/``auto`` zones, the micro
  half of the hand-over (:class:`~conveyor_twin.split.mirror.MicroSide`);
- :class:`MacroRole`: the macro stage and the hand-over on a mirror of the micro state
  (:class:`~conveyor_twin.split.mirror.MacroSide`).

Each scale role is a :class:`~conveyor_twin.split.scale.ScaleRole` with its own output (its
stage's producer only). The composed layout is :func:`conveyor_twin.coord.assembly.build_twin`.
"""

from typing import Callable, Dict, Optional

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.assembly import macro_zone_parts, micro_zone_parts
from conveyor_twin.coord.layout import Role
from conveyor_twin.coord.requests import SpawnRequest
from conveyor_twin.coord.stages import MacroStage, MicroStage
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coord.twin import Twin
from conveyor_twin.coupling.zone_barriers import RemoteBarriers
from conveyor_twin.faults.material import holds_part
from conveyor_twin.faults.scenario import Scenario, ScenarioRunner
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import MacroOutput, MicroOutput
from conveyor_twin.split import protocol
from conveyor_twin.split.mirror import has_coupling, MacroSide, MicroSide
from conveyor_twin.split.remote import RemoteStage, Transport
from conveyor_twin.split.scale import ScaleRole


class CoordinatorRole:
    """The coordinator process: time, commands, actuation; its stage is the scale processes.

    :param transport: the coupling topics (ROS side).
    :param pids: the scale processes' ids by role, if known.
    """

    def __init__(self, cell: Cell, *, seed: int, transport: Transport,
                 pids: Optional[Dict[Role, int]] = None) -> None:
        self.cell, self.seed = cell, seed
        self.remote = RemoteStage(cell, transport, pids=pids)
        self.twin = Twin(cell, seed=seed, stages=[self.remote],
                         actuator_load=self.remote.actuator_load)

    def spawn(self, request: SpawnRequest) -> np.ndarray:
        """Place a checked spawn request's parts now (all or nothing); return their ids.

        :raises ValueError: with the micro process's reason if nothing was placed.
        """
        return self.remote.spawn(request.type_index, request.x, request.y, request.yaw)

    def arm_scenario(self, scenario: Scenario) -> ScenarioRunner:
        """Arm a fault scenario on the coordinator core (re-armed after every reset); its
        triggers read what the scale processes measure after every step."""
        self.remote.measures_wanted = scenario.conditional
        runner = ScenarioRunner(scenario, self.twin.faults,
                                edge_count=self.remote.measured_edge_count,
                                zone_parts=self.remote.measured_zone_parts)
        self.twin.fault_watchers.append(runner.watch)
        self.twin.reset_listeners.append(runner.arm)
        return runner


class MicroRole(ScaleRole):
    """The micro process: the micro stage, and the micro half of the hand-over (cells with
    ``macro``/``auto`` zones: it sends its state after the step, replays the edits back)."""

    def __init__(self, cell: Cell, *, seed: int) -> None:
        self.side: Optional[MicroSide] = None
        if has_coupling(cell):
            barriers = RemoteBarriers()
            stage = MicroStage(cell, seed, macro_barriers=barriers)
            self.side = MicroSide(stage, barriers)
        else:
            stage = MicroStage(cell, seed)
        super().__init__(Role.MICRO, stage, TwinOutput([MicroOutput(stage)]),
                         exchanges=self.side is not None)

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart the stage and forget the barrier values of ``macro`` zones."""
        super().reset(cell, seed)
        if self.side is not None:
            self.side.reset()

    def exchange(self, inp: StepInput) -> None:
        """Send the step's micro state to the macro process (its edits finish the step)."""
        self.link.send_exchange(protocol.to_cdr(protocol.stamped(inp.step,
                                                                 self.side.state_bytes())))

    def on_exchange(self, data: bytes) -> None:
        """Replay the macro process's hand-over edits of the pending step, then finish it."""
        step, body = protocol.parse_stamped(protocol.from_cdr(data))
        inp = self._pending
        if inp is None or step != inp.step:
            pending = None if inp is None else inp.step
            self.link.error(f'hand-over edits of step {step} while step {pending} is pending; '
                            'ignored')
            return
        self._pending = None
        self.side.apply(body)
        self.finish_step(inp)

    def actuator_loads(self) -> Optional[np.ndarray]:
        """The step's load on every actuator [N] (None without actuators)."""
        return self.stage.actuator_load() if self.stage.cell.actuators else None

    def spawn_reply(self, body: bytes) -> bytes:
        """Place parts for a spawn request: ``E`` + message, or ``I`` + ids."""
        type_index, x, y, yaw = protocol.parse_spawn(body)
        try:
            ids = self.stage.spawn(type_index, x, y, yaw)
        except ValueError as exc:
            return protocol.spawn_error(str(exc))
        return protocol.spawn_reply(ids)

    def part_reply(self, body: bytes) -> bytes:
        """Answer whether the micro scale holds a part of the queried id now (``part_jam``)."""
        return protocol.part_reply(holds_part(self.stage.sim, protocol.parse_part_query(body)))

    def trigger_measures(self) -> Callable[[], bytes]:
        """Return the barrier edge counts and bodies per zone after a step, as bytes."""
        micro, zones = self.stage, range(len(self.stage.cell.zones))
        return lambda: protocol.encode_measures(
            micro.barrier_edge_count(),
            np.array([micro_zone_parts(micro.cell, micro, i) for i in zones]))


class MacroRole(ScaleRole):
    """The macro process: the macro stage, and for cells with ``macro``/``auto`` zones the
    hand-over on a mirror of the micro state (its counters then carry the cell's ledger).

    :param check_balance: check the part ledger after every hand-over (None: from the
        environment, as :class:`~conveyor_twin.coupling.scale.ScaleCoupling`).
    """

    def __init__(self, cell: Cell, *, seed: int, check_balance: Optional[bool] = None) -> None:
        stage = MacroStage(cell, seed)
        # the mirror never runs sources: its seed does not matter
        self.side = (MacroSide(stage, cell, 0, check=check_balance) if has_coupling(cell)
                     else None)
        self._states: Dict[int, memoryview] = {}  # micro states by step, arrived early
        super().__init__(Role.MACRO, stage, TwinOutput([MacroOutput(stage)]),
                         exchanges=self.side is not None)

    def counters(self) -> Dict[str, float]:
        """Part balance of the grids, with the whole cell's ledger (``balance_*``) when the
        hand-over runs here."""
        out = self.stage.counters()
        if self.side is not None:
            out.update(self.side.coupling.balance_counters())
        return out

    def reset(self, cell: Cell, seed: int) -> None:
        """Restart the grids and the hand-over; drop micro states that arrived early."""
        super().reset(cell, seed)
        if self.side is not None:
            self.side.reset(cell, 0)  # the mirror never runs sources
        self._states.clear()

    def exchange(self, inp: StepInput) -> None:
        """Hand over once the micro state of the step has arrived."""
        self._couple()

    def on_exchange(self, data: bytes) -> None:
        """Keep the micro state of a step; hand over if that step is pending."""
        step, body = protocol.parse_stamped(protocol.from_cdr(data))
        self._states[step] = body
        self._couple()

    def _couple(self) -> None:
        """Run the hand-over of the pending step if its micro state is here; finish it."""
        inp = self._pending
        if inp is None or inp.step not in self._states:
            return
        state = self._states.pop(inp.step)
        if self._states:
            stale = sorted(self._states)
            self.link.error(f'micro states of steps {stale} unused; dropped')
            self._states.clear()
        self._pending = None
        reply = self.side.couple(inp, state)
        self.link.send_exchange(protocol.to_cdr(protocol.stamped(inp.step, reply)))
        self.finish_step(inp)

    def trigger_measures(self) -> Callable[[], bytes]:
        """Return the density's parts per zone after a step, as bytes (no barrier counts)."""
        macro, zones = self.stage, range(len(self.stage.cell.zones))
        return lambda: protocol.encode_measures(
            np.zeros(0, np.uint32), np.array([macro_zone_parts(macro.cell, macro, i)
                                              for i in zones]))


def build_scale_role(role: Role, cell: Cell, *, seed: int,
                     check_balance: Optional[bool] = None) -> ScaleRole:
    """Build the scale process ``role`` (:attr:`Role.MICRO` or :attr:`Role.MACRO`) of ``cell``.

    :raises ValueError: for the coordinator role (:class:`CoordinatorRole` needs a transport).
    """
    if role is Role.MICRO:
        return MicroRole(cell, seed=seed)
    if role is Role.MACRO:
        return MacroRole(cell, seed=seed, check_balance=check_balance)
    raise ValueError(f'{Role(role).name.lower()} is no scale role (allowed: micro, macro)')
