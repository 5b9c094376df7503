"""A node's contract streams published from the twin's frames (a frame sink).

:class:`StreamPublisher` creates one publisher per stream it is given (from the contract table)
and, for every frame, publishes the bytes the frame holds for those streams
(:data:`conveyor_twin.contract.FRAME` says where) with
:class:`~conveyor_twin.ros.qos.RawPublisher` (no message objects, refusals counted). A stream
the frame does not carry in this process is skipped. Its node answers a lockstep reader's
hello once its writers reach that reader (:mod:`conveyor_twin.ros.reader_handshake`).
"""

from operator import attrgetter
from typing import Any, Dict, Sequence

from conveyor_twin import contract
from conveyor_twin.contract import Shape
from conveyor_twin.output.frame import Frame
from conveyor_twin.ros.endpoints import create_publisher
from conveyor_twin.ros.qos import RawPublisher
from conveyor_twin.ros.reader_handshake import HandshakeResponder


class StreamPublisher:
    """Publish ``streams`` of every frame on ``node``.

    :param node: the rclpy node that owns the publishers.
    :param streams: contract streams (those of :data:`conveyor_twin.output.frame.FRAME_STREAMS`
        are published from the frames; others, e.g. ``markers``, only get their publisher).
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
        #: Answers readers that wait until the node's writers reach them.
        self.handshake = HandshakeResponder(node)
        slots = [(attrgetter(s.attribute), raw[s.topic], s.shape) for s in contract.FRAME
                 if s.topic in raw]
        self._one = tuple((get, send) for get, send, shape in slots if shape is Shape.ONE)
        self._stamped = tuple((get, send) for get, send, shape in slots
                              if shape is Shape.STAMPED)
        self._many = tuple((get, send) for get, send, shape in slots if shape is Shape.MANY)

    def on_frame(self, frame: Frame) -> None:
        """Publish this node's streams of the frame."""
        for get, publish in self._one:
            data = get(frame)
            if data is not None:
                publish(data)
        for get, publish in self._stamped:
            for _, data in get(frame):
                publish(data)
        for get, publish in self._many:
            for data in get(frame):
                publish(data)
