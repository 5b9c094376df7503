"""The frame: what the twin emitted in one step, every contract stream as CDR bytes.

A :class:`Frame` holds, for the step just taken, the CDR bytes (with the 4-byte encapsulation
header, as a ROS publisher sends them) of every stream of :mod:`conveyor_twin.contract` that
the stages in this process produce, the accepted commands that took effect at the step and,
on diagnostics steps, the diagnostics. Streams stamped with the step carry ``time_ns``; each
light-barrier edge carries its own interpolated time. A stream not produced in this process
(split layout: the micro process has no ``/clock``) is ``None`` or empty.

The twin builds one frame per step and hands the same object to every sink
(:class:`~conveyor_twin.output.hub.TwinOutput`); the object is reused the next step, so a sink
that keeps data beyond :meth:`on_frame <FrameSink.on_frame>` keeps the bytes (immutable) or a
:meth:`Frame.copy`, never the frame.
"""

from typing import Iterator, Protocol, Sequence, Tuple

from conveyor_twin import contract
from conveyor_twin.contract import Shape, Topic

#: The streams of a frame in the order :meth:`Frame.messages` yields them
#: (:data:`conveyor_twin.contract.FRAME`).
FRAME_STREAMS: Tuple[Topic, ...] = tuple(slot.topic for slot in contract.FRAME)


class Frame:
    """The output of one step (attributes are set by the producers, read by the sinks).

    Besides ``step``, ``time_ns``, ``input`` and ``commands``, a frame has one attribute per
    entry of :data:`conveyor_twin.contract.FRAME` (its ``attribute``), holding that stream's
    bytes as its ``shape`` says, or its ``empty`` value when the step emitted none of it.

    :ivar step: step index (the state after it) [1].
    :ivar time_ns: simulation time of the step [ns]; the stamp of every stream but the edges.
    :ivar input: the step's :class:`~conveyor_twin.coord.step_input.StepInput` (actual belt
        speeds [m/s] and actuator positions [m or rad] every stage advanced with).
    :ivar commands: accepted :class:`~conveyor_twin.coord.commands.Command` objects that took
        effect at this step, in order (coordinator's part).
    :ivar clock: ``rosgraph_msgs/Clock`` CDR (coordinator).
    :ivar belt_states: ``BeltStates`` CDR (coordinator).
    :ivar actuator_states: ``ActuatorStates`` CDR (coordinator).
    :ivar diagnostics: ``DiagnosticArray`` CDR on diagnostics steps, else None (coordinator).
    :ivar parts: ``PartStates`` CDR (micro).
    :ivar light_barriers: ``LightBarrierStates`` CDR (micro).
    :ivar edges: ``(stamp [ns], LightBarrierEdge CDR)`` of every edge of the step (micro).
    :ivar density: one ``DensityGrid`` CDR per macro zone, in the cell's zone order (macro).
    :ivar faults: ``FaultState`` CDR on the first step and whenever the active faults change,
        else None (coordinator).
    """

    __slots__ = ('step', 'time_ns', 'input', 'commands') + tuple(
        slot.attribute for slot in contract.FRAME)

    def __init__(self) -> None:
        self.step = 0
        self.time_ns = 0
        self.input = None
        self.commands: Sequence = ()
        for slot in contract.FRAME:
            setattr(self, slot.attribute, slot.empty)

    def messages(self) -> Iterator[Tuple[Topic, int, bytes]]:
        """Yield (contract topic, stamp [ns], CDR bytes) of every message of the frame, in the
        order of :data:`FRAME_STREAMS` (edges and density zones in their order)."""
        t = self.time_ns
        for slot in contract.FRAME:
            value = getattr(self, slot.attribute)
            shape = slot.shape
            if shape is Shape.ONE:
                if value is not None:
                    yield slot.topic, t, value
            elif shape is Shape.STAMPED:
                for stamp, data in value:
                    yield slot.topic, stamp, data
            else:
                for data in value:
                    yield slot.topic, t, data

    def copy(self) -> 'Frame':
        """Return a frame with the same bytes that the next step does not overwrite."""
        other = Frame()
        for name in self.__slots__:
            setattr(other, name, getattr(self, name))
        other.commands = tuple(self.commands)
        for slot in _SEQUENCES:
            setattr(other, slot.attribute, tuple(getattr(self, slot.attribute)))
        return other


_SEQUENCES = tuple(slot for slot in contract.FRAME if slot.shape is not Shape.ONE)


class FrameSink(Protocol):
    """Something that takes the twin's frames (a ROS publisher, the recorder, a viewer).

    :meth:`on_frame` runs on the stepping thread: it must return quickly and never block
    (hand slow work to :class:`~conveyor_twin.output.queued.QueuedSink`). A sink may also
    define ``on_message(topic, stamp_ns, data)`` for what the twin emits off the step
    (``markers``, built at viewer rate on a thread of their own).
    """

    def on_frame(self, frame: Frame) -> None:
        """Take the frame of the step just taken (valid during this call only)."""
