"""Reading what a controller reads: the latest state of every stream the harness received."""

from typing import Any, Dict, List, Optional

from conveyor_twin_msgs.msg import ActuatorStates, BeltStates, LightBarrierEdge
from diagnostic_msgs.msg import DiagnosticStatus
import numpy as np
from rclpy.serialization import deserialize_message

from conveyor_twin import contract
from conveyor_twin.testing import checks
from conveyor_twin.testing._layout import density_per_step
from conveyor_twin.testing.driver import command_origin, command_result
from conveyor_twin.testing.lifecycle import TwinLifecycle
from conveyor_twin.testing.states import (ActuatorState, BarrierState, BeltSample, BeltState,
                                          CommandRecord, Edge)
from conveyor_twin.wire import cdr

PartStates = cdr.PartStatesData
DensityGrid = cdr.DensityGridData


class StreamReader(TwinLifecycle):
    """The reading part of :class:`~conveyor_twin.testing.LockstepTwin`: every method reads
    what the harness's probe received, never the twin's internals."""

    @property
    def time(self) -> float:
        """Simulation time of the last step [s]."""
        return self.time_ns * 1e-9

    def _received(self, topic: str) -> List[bytes]:
        return self._check_open(f'reading {topic}').probe.received[topic]

    def messages(self, topic: str) -> List[bytes]:
        """Every message received on a stream since the start or the last reset, as CDR bytes
        (``parts``, ``density``, ``light_barriers``, ``light_barrier_edges``, ``belt_states``,
        ``actuator_states``, ``/clock``, ``command_status``)."""
        return self._received(topic)

    def digest(self, topic: str) -> str:
        """SHA-256 of every message received on ``topic`` (same seed and commands: same)."""
        self._check_open('digest()')
        return self._driver.probe.digest(topic)

    def belts(self) -> Dict[str, BeltState]:
        """Latest ``belt_states``: ``{belt: BeltState}`` (empty before the first step)."""
        data = self._received(contract.BELT_STATES.name)
        if not data:
            return {}
        msg = deserialize_message(data[-1], BeltStates)
        return {n: BeltState(c, s) for n, c, s in zip(msg.name, msg.commanded_speed, msg.speed)}

    def belt(self, name: str) -> BeltState:
        """Latest state of one belt; raise KeyError naming the known belts."""
        return _pick(self.belts(), name, 'belt')

    def belt_history(self, name: str) -> List[BeltSample]:
        """Every ``belt_states`` entry of one belt received so far, oldest first."""
        out = []
        for data in self._received(contract.BELT_STATES.name):
            msg = deserialize_message(data, BeltStates)
            if name not in msg.name:
                raise KeyError(f'unknown belt {name!r} (known: {", ".join(msg.name)})')
            i = list(msg.name).index(name)
            out.append(BeltSample(cdr.stamp_of(data), msg.commanded_speed[i], msg.speed[i]))
        return out

    def actuators(self) -> Dict[str, ActuatorState]:
        """Latest ``actuator_states``: ``{actuator: ActuatorState}``."""
        data = self._received(contract.ACTUATOR_STATES.name)
        if not data:
            return {}
        msg = deserialize_message(data[-1], ActuatorStates)
        return {n: ActuatorState(c, p, bool(s), float(f)) for n, c, p, s, f in
                zip(msg.name, msg.commanded_position, msg.position, msg.stalled, msg.load)}

    def actuator(self, name: str) -> ActuatorState:
        """Latest state of one actuator; raise KeyError naming the known actuators."""
        return _pick(self.actuators(), name, 'actuator')

    def barriers(self) -> Dict[str, BarrierState]:
        """Latest ``light_barriers``: ``{barrier: BarrierState}``."""
        data = self._received(contract.LIGHT_BARRIERS.name)
        if not data:
            return {}
        _, _, _, names, blocked, counts = cdr.decode_light_barrier_states(data[-1])
        return {n: BarrierState(bool(b), int(c)) for n, b, c in zip(names, blocked, counts)}

    def barrier(self, name: str) -> BarrierState:
        """Latest state of one light barrier; raise KeyError naming the known barriers."""
        return _pick(self.barriers(), name, 'light barrier')

    def edges(self, *, since_step: int = 0, name: Optional[str] = None) -> List[Edge]:
        """Light-barrier edges of steps after ``since_step``, in order (optionally one barrier's).

        :param since_step: only edges that happened after this step index
        :param name: only this barrier's edges
        """
        checks.integer('since_step', since_step, 0)
        step_ns = round(self.step_s * 1e9)
        out = []
        for data in self._received(contract.LIGHT_BARRIER_EDGES.name):
            msg = deserialize_message(data, LightBarrierEdge)
            t = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            step = -(-t // step_ns)
            if step > since_step and (name is None or msg.name == name):
                out.append(Edge(msg.name, msg.blocked, msg.part_id, t, step))
        return out

    def parts(self) -> PartStates:
        """Latest ``parts``: ids, types, poses and velocities as numpy arrays (SI units)."""
        data = self._received(contract.PARTS.name)
        if not data:
            empty = np.zeros(0)
            return PartStates(0, self.cell.settings.frame_id, 0, empty.astype(np.uint32),
                              empty.astype(np.uint16), *([empty] * 6))
        return cdr.decode_part_states(data[-1])

    def part(self, part_id: int) -> Optional[Dict[str, float]]:
        """Latest pose and velocity of one micro part (None when it is not in the micro scale
        any more: left through a sink or handed over to the macro scale)."""
        checks.integer('part_id', part_id, 0, checks.UINT32_MAX)
        parts = self.parts()
        hits = np.flatnonzero(parts.id == part_id)
        if not len(hits):
            return None
        i = hits[0]
        return {f: float(getattr(parts, f)[i]) for f in ('x', 'y', 'yaw', 'vx', 'vy', 'wz')}

    def densities(self) -> Dict[str, DensityGrid]:
        """Latest ``density`` of every macro zone: ``{zone: grid}``, density shape (ny, nx)."""
        out: Dict[str, DensityGrid] = {}
        data = self._received(contract.DENSITY.name)
        for raw in data[-max(1, density_per_step(self.cell)):]:
            grid = cdr.decode_density_grid(raw)
            out[grid.zone] = grid
        return out

    def command_log(self) -> List[CommandRecord]:
        """Every command the twin answered so far (the harness's and every controller's)."""
        out = []
        for data in self._received(contract.COMMAND_STATUS.name):
            status = deserialize_message(data, DiagnosticStatus)
            values = {kv.key: kv.value for kv in status.values}
            sender, sequence = command_origin(status)
            out.append(CommandRecord(status.name, status.hardware_id,
                                     float(values.get('value', 'nan')), command_result(status),
                                     sender, sequence))
        return out

    def describe_state(self) -> str:
        """One line of the twin's state as the harness last saw it (for failure messages)."""
        if self._closed:
            return 'closed'
        belts = ', '.join(f'{n} {s.speed:.3g}/{s.commanded_speed:.3g} m/s'
                          for n, s in self.belts().items())
        actuators = ', '.join(f'{n} {s.position:.3g}/{s.commanded_position:.3g}'
                              for n, s in self.actuators().items())
        blocked = [n for n, s in self.barriers().items() if s.blocked]
        rejected = [r.result.reason for r in self.command_log() if not r.result.accepted]
        return (f'step {self.step_index} (t = {self.time:.3f} s); belts (actual/commanded): '
                f'{belts or "-"}; actuators: {actuators or "-"}; blocked barriers: '
                f'{", ".join(blocked) or "none"}; {len(self.parts().id)} micro parts; '
                f'{len(self._received(contract.LIGHT_BARRIER_EDGES.name))} edges; '
                f'{len(rejected)} rejected commands' + (f' (last: {rejected[-1]})'
                                                        if rejected else ''))


def _pick(states: Dict[str, Any], name: str, kind: str) -> Any:
    try:
        return states[name]
    except KeyError:
        known = ', '.join(states) or 'none received yet: step first'
        raise KeyError(f'unknown {kind} {name!r} (known: {known})') from None
