"""The in-process recorder as a sink of the twin's frames (no ROS, no re-parsed stamps).

:class:`RecordingSink` declares a channel for every stream of the contract (plus ``markers``)
and hands each frame's bytes to a :class:`~conveyor_twin.record.writer.McapRecorder` with the
stamp the frame carries: the step's time, an edge's own time. The recorder only appends to a
bounded queue (a full queue drops and counts per topic), so the step never waits for the
disk. Accepted commands are recorded with the step at which they took effect; accepted
``spawn_parts``/``reset`` calls through :meth:`RecordingSink.record_call`.

What is recorded is byte for byte what the nodes publish: both take the same frame.
"""

from typing import Dict, Sequence

from conveyor_twin import contract
from conveyor_twin.coord.commands import BELT, Command
from conveyor_twin.output.frame import Frame
from conveyor_twin.record.topics import resolve
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.wire import cdr


def encode_command(command: Command) -> bytes:
    """Return the BeltCommand/ActuatorCommand CDR of an accepted command, with the sender and
    sequence number it arrived with."""
    if command.kind == BELT:
        return cdr.encode_belt_command(command.name, command.value, command.sender,
                                       command.sequence)
    return cdr.encode_actuator_command(command.name, command.value, command.sender,
                                       command.sequence)


class RecordingSink:
    """Record every frame (and off-step ``markers``) into an open :class:`McapRecorder`.

    :param recorder: the open recorder (the caller closes it).
    :param namespace: ROS namespace of the twin's topics (recorded names are absolute).
    :param streams: the contract streams to declare (default: every stream).
    """

    def __init__(self, recorder: McapRecorder, *, namespace: str = '',
                 streams: Sequence[contract.Topic] = contract.STREAMS) -> None:
        self.recorder = recorder
        self.topics: Dict[str, contract.Topic] = {}
        self._name: Dict[contract.Topic, str] = {}
        for topic in streams:
            name = resolve(topic.name, namespace)
            recorder.add_topic(name, topic.type_name, qos=topic.qos)
            self.topics[name] = topic
            self._name[topic] = name
        names = self._name
        self._clock = names.get(contract.CLOCK)
        self._belts = names.get(contract.BELT_STATES)
        self._actuators = names.get(contract.ACTUATOR_STATES)
        self._diagnostics = names.get(contract.DIAGNOSTICS)
        self._parts = names.get(contract.PARTS)
        self._barriers = names.get(contract.LIGHT_BARRIERS)
        self._edges = names.get(contract.LIGHT_BARRIER_EDGES)
        self._density = names.get(contract.DENSITY)
        self._faults = names.get(contract.FAULTS)

    def on_frame(self, frame: Frame) -> None:
        """Queue every message of the frame with its stamp, then its accepted commands."""
        record = self.recorder.record
        t = frame.time_ns
        for name, data in ((self._clock, frame.clock), (self._belts, frame.belt_states),
                           (self._actuators, frame.actuator_states),
                           (self._diagnostics, frame.diagnostics), (self._parts, frame.parts),
                           (self._barriers, frame.light_barriers), (self._faults, frame.faults)):
            if data is not None and name is not None:
                record(name, t, data)
        if self._edges is not None:
            for stamp, data in frame.edges:
                record(self._edges, stamp, data)
        if self._density is not None:
            for data in frame.density:
                record(self._density, t, data)
        for command in frame.commands:
            self.recorder.record_accepted_command(command.kind, t, encode_command(command))

    def on_message(self, topic: contract.Topic, stamp_ns: int, data: bytes) -> None:
        """Queue a message emitted off the step (``markers``) at ``stamp_ns``."""
        name = self._name.get(topic)
        if name is not None:
            self.recorder.record(name, stamp_ns, data)

    def record_call(self, kind: str, time_ns: int, data: bytes) -> None:
        """Record an accepted ``spawn_parts`` (``'spawn'``) or ``reset`` call [ns]."""
        self.recorder.record_accepted_command(kind, time_ns, data)
