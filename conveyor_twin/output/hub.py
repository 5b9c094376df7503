"""The twin's output: builds one frame per step and hands it to every sink.

:class:`TwinOutput` is a step listener of the coordinator core
(``twin.step_listeners.append(output.on_step)``) or, in a split scale process, is called by
the node when its step is done. Each step it lets its producers (the stages of this process)
write the frame, then calls every subscribed sink's ``on_frame`` in subscription order, on the
stepping thread. Sinks are the ROS publishers of the nodes, the in-process recorder,
re-simulation, a viewer or a test harness; none of them is known to the cores.
"""

import threading
from typing import Any, Callable, Dict, Optional, Sequence, Tuple

from conveyor_twin.contract import FRAME, Topic
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.health import Health
from conveyor_twin.output.frame import Frame, FrameSink
from conveyor_twin.output.producers import FrameProducer


#: Frame attribute of every stream a ``stream_outage`` may silence, and its value when silent.
_OUTAGE = {slot.topic.name: (slot.attribute, slot.empty) for slot in FRAME if slot.outage}


class TwinOutput:
    """One frame per step from ``producers``, handed to every subscribed sink.

    :param producers: the frame parts built in this process, in frame order (coordinator,
        micro, macro).
    """

    def __init__(self, producers: Sequence[FrameProducer]) -> None:
        self.producers: Tuple[FrameProducer, ...] = tuple(producers)
        self.frame = Frame()
        self._lock = threading.Lock()
        self._sinks: Tuple[Any, ...] = ()
        self._on_frame: Tuple[Callable[[Frame], None], ...] = ()
        self._on_message: Tuple[Callable[[Topic, int, bytes], None], ...] = ()
        #: Streams silenced by ``stream_outage`` faults: fault id -> (frame attribute, empty).
        self.outages: Dict[int, Tuple[str, Any]] = {}
        #: The health of the twin whose frames this is (set by whoever attaches the output to
        #: a twin): a sink with a thread of its own reports its failure there.
        self.health: Optional[Health] = None

    def _outages(self, inp: StepInput) -> None:
        """Take the step's ``stream_outage`` events."""
        for event in inp.faults:
            fault = event.fault
            if fault.kind != 'stream_outage':
                continue
            if event.action == 'clear':
                self.outages.pop(fault.id, None)
            else:
                self.outages[fault.id] = _OUTAGE[fault.target]

    def subscribe(self, sink: FrameSink) -> None:
        """Hand every following frame to ``sink.on_frame`` (and off-step messages to its
        ``on_message``, if it has one). Safe while the twin steps: from the next step on."""
        with self._lock:
            self._set(self._sinks + (sink,))

    def unsubscribe(self, sink: FrameSink) -> None:
        """Stop handing frames to ``sink`` (no error if it is not subscribed)."""
        with self._lock:
            self._set(tuple(s for s in self._sinks if s is not sink))

    def _set(self, sinks: Tuple[Any, ...]) -> None:
        self._sinks = sinks
        on_message = tuple(s.on_message for s in sinks if hasattr(s, 'on_message'))
        # one assignment each: the stepping thread reads whole tuples
        self._on_frame = tuple(s.on_frame for s in sinks)
        self._on_message = on_message

    @property
    def sinks(self) -> Tuple[Any, ...]:
        """The subscribed sinks, in order."""
        return self._sinks

    def on_step(self, inp: StepInput, commands: Sequence = ()) -> Frame:
        """Build the frame of the step just taken and hand it to every sink; return it.

        :param inp: the step's input (step index, time, actuation).
        :param commands: accepted commands that took effect at the step.
        """
        frame = self.frame
        frame.step = inp.step
        frame.time_ns = inp.time_ns
        frame.input = inp
        for producer in self.producers:
            producer.fill(frame, inp, commands)
        if inp.step == 1 and self.outages:  # a reset ends every fault
            self.outages = {}
        if inp.faults:
            self._outages(inp)
        if self.outages:
            for attribute, empty in self.outages.values():
                setattr(frame, attribute, empty)
        for on_frame in self._on_frame:
            on_frame(frame)
        return frame

    def emit(self, topic: Topic, data: bytes, stamp_ns: Optional[int] = None) -> None:
        """Hand a message emitted off the step (``markers``) to the sinks' ``on_message``.

        :param stamp_ns: its simulation time [ns]; None: the time of the latest frame.
        """
        stamp = self.frame.time_ns if stamp_ns is None else stamp_ns
        for on_message in self._on_message:
            on_message(topic, stamp, data)
