"""The in-process recorder as a sink of the twin's frames (no ROS, no re-parsed stamps).

:class:`RecordingSink` declares a channel for every stream of the contract (plus ``markers``)
and hands each frame's bytes to a :class:`~conveyor_twin.record.writer.McapRecorder` with the
stamp the frame carries: the step's time, an edge's own time. The recorder only appends to a
bounded queue (a full queue drops and counts per topic), so the step never waits for the
disk. Accepted commands are recorded with the step at which they took effect; accepted
``spawn_parts``/``reset`` calls through :meth:`RecordingSink.record_call`.

What is recorded is byte for byte what the nodes publish: both take the same frame.
"""

from operator import attrgetter
from typing import Dict, Sequence

from conveyor_twin import contract
from conveyor_twin.contract import Shape
from conveyor_twin.coord.commands import Command, CommandKind
from conveyor_twin.output.frame import Frame
from conveyor_twin.record.topics import resolve
from conveyor_twin.record.writer import McapRecorder
from conveyor_twin.wire import cdr


def encode_command(command: Command) -> bytes:
    """Return the BeltCommand/ActuatorCommand CDR of an accepted command, with the sender and
    sequence number it arrived with."""
    if command.kind == CommandKind.BELT:
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
        # (recorded name, frame attribute getter) of every declared frame stream, by shape;
        # the frame table lists the one-message streams first, so this is its order
        slots = [(self._name[s.topic], attrgetter(s.attribute), s.shape)
                 for s in contract.FRAME if s.topic in self._name]
        self._one = tuple((n, get) for n, get, shape in slots if shape is Shape.ONE)
        self._stamped = tuple((n, get) for n, get, shape in slots if shape is Shape.STAMPED)
        self._many = tuple((n, get) for n, get, shape in slots if shape is Shape.MANY)

    def on_frame(self, frame: Frame) -> None:
        """Queue every message of the frame with its stamp (in the order of
        :data:`conveyor_twin.contract.FRAME`), then its accepted commands."""
        record = self.recorder.record
        t = frame.time_ns
        for name, get in self._one:
            data = get(frame)
            if data is not None:
                record(name, t, data)
        for name, get in self._stamped:
            for stamp, data in get(frame):
                record(name, stamp, data)
        for name, get in self._many:
            for data in get(frame):
                record(name, t, data)
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
