"""A node's contract streams published from the twin's frames (a frame sink).

:class:`StreamPublisher` creates one publisher per stream it is given (from the contract table)
and, for every frame, publishes the bytes the frame holds for those streams with
:class:`~conveyor_twin.ros.qos.RawPublisher` (no message objects, refusals counted). A stream
the frame does not carry in this process is skipped.
"""

from operator import attrgetter
from typing import Any, Dict, Sequence

from conveyor_twin import contract
from conveyor_twin.output.frame import Frame
from conveyor_twin.ros.endpoints import create_publisher
from conveyor_twin.ros.qos import RawPublisher

#: Frame attribute of every stream with one message per step (or none).
_SINGLE = {contract.CLOCK: 'clock', contract.BELT_STATES: 'belt_states',
           contract.ACTUATOR_STATES: 'actuator_states', contract.DIAGNOSTICS: 'diagnostics',
           contract.PARTS: 'parts', contract.LIGHT_BARRIERS: 'light_barriers',
           contract.FAULTS: 'faults'}


class StreamPublisher:
    """Publish ``streams`` of every frame on ``node``.

    :param node: the rclpy node that owns the publishers.
    :param streams: contract streams (those of :data:`conveyor_twin.output.frame.FRAME_STREAMS`).
    """

    def __init__(self, node: Any, streams: Sequence[contract.Topic]) -> None:
        logger = node.get_logger()
        #: rclpy publisher of every stream.
        self.publishers: Dict[contract.Topic, Any] = {}
        raw: Dict[contract.Topic, RawPublisher] = {}
        for topic in streams:
            self.publishers[topic] = create_publisher(node, topic)
            raw[topic] = RawPublisher(self.publishers[topic], logger)
        self.raw_publishers = tuple(raw.values())
        self._single = tuple((attrgetter(_SINGLE[t]), raw[t]) for t in raw if t in _SINGLE)
        self._edges = raw.get(contract.LIGHT_BARRIER_EDGES)
        self._density = raw.get(contract.DENSITY)

    def on_frame(self, frame: Frame) -> None:
        """Publish this node's streams of the frame."""
        for get, publish in self._single:
            data = get(frame)
            if data is not None:
                publish(data)
        if self._edges is not None:
            for _, data in frame.edges:
                self._edges(data)
        if self._density is not None:
            for data in frame.density:
                self._density(data)
