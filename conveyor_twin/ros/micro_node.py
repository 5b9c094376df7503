"""``micro_simulator``: publishes every micro part, the light barriers and their edges.

Composed, its stage is stepped by the coordinator in the same process; as its own process
(``ros2 run conveyor_twin micro_simulator`` or ``python -m conveyor_twin.ros.micro_node``) it
serves the split layout's micro role (:class:`~conveyor_twin.split.roles.MicroRole`), which
follows the coordinator's step inputs over the coupling topic and, for a cell with
``macro``/``auto`` zones, exchanges the hand-over with the macro node
(:mod:`conveyor_twin.split.mirror`).
"""

import sys
import threading
from typing import List, Optional


from conveyor_twin import contract
from conveyor_twin.coord.layout import Role
from conveyor_twin.coord.runner import raise_thread_priority
from conveyor_twin.coord.stages import MicroStage
from conveyor_twin.output.frame import Frame
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.markers import CellMarkers
from conveyor_twin.ros.endpoints import create_publisher
from conveyor_twin.ros.qos import raw_publish
from conveyor_twin.ros.scale_node import ScaleNode
from conveyor_twin.ros.standalone import run_scale_node
from conveyor_twin.ros.stream_publisher import StreamPublisher

#: The streams this node publishes from the frames (markers it builds itself).
STREAMS = contract.frame_streams(contract.Producer.MICRO)
#: Name of the markers thread (and of its failure in the twin's health).
MARKERS_THREAD = 'markers thread'


class MicroNode(ScaleNode):
    """Publish ``parts``, ``light_barriers``, ``light_barrier_edges`` and part ``markers``.

    A sink of the twin's frames: it publishes the micro part of every frame of ``output``.

    :param stage: the micro stage.
    :param output: the output to subscribe to (composed: shared by the three nodes; split: the
        micro role's, which builds a frame when its step is done).
    :param kwargs: as :class:`ScaleNode` (``server``: the split layout's micro role).
    """

    def __init__(self, stage: MicroStage, *, output: TwinOutput, **kwargs) -> None:
        super().__init__('micro_simulator', stage, **kwargs)
        cell = stage.cell
        self.output = output
        self._markers = CellMarkers(cell)
        self.streams = StreamPublisher(self, STREAMS)
        self.parts_pub = self.streams.publishers[contract.PARTS]
        self.barrier_pub = self.streams.publishers[contract.LIGHT_BARRIERS]
        self.edge_pub = self.streams.publishers[contract.LIGHT_BARRIER_EDGES]
        self.markers_pub = create_publisher(self, contract.MARKERS)
        self._pub_markers = raw_publish(self.markers_pub, self.get_logger())
        self._markers_due = None
        self.markers_priority = 0  # SCHED_FIFO priority of the markers thread (0: normal)
        self._markers_closed = False
        self._markers_wake = threading.Event()
        self._markers_thread = None
        if self.markers_every:  # its exception is reported to the health, once
            self._markers_thread = threading.Thread(
                target=self.health.guard(MARKERS_THREAD, self._markers_loop),
                name='conveyor_twin_markers', daemon=True)
            self._markers_thread.start()
        self.output.subscribe(self.streams)
        if self.markers_every:
            self.output.subscribe(self)  # on_frame: hands the due markers' state over
        self.serve_coordinator()

    def on_frame(self, frame: Frame) -> None:
        """Hand the state of a step due for markers to the markers thread (the frame's
        streams are published by :attr:`streams`, subscribed before)."""
        if frame.step % self.markers_every == 0:
            _, part_type, x, y = self.stage.parts()[:4]
            # copies (a few us) here; the ~0.5 ms of building happens off the stepping thread
            self._markers_due = (frame.time_ns, part_type.copy(), x.copy(), y.copy(),
                                 self.stage.barrier_blocked().copy(),
                                 frame.input.actuator_position.copy())
            self._markers_wake.set()

    def _markers_loop(self) -> None:
        """Build and publish the latest due MarkerArray (viewer rate, off the step thread)."""
        applied = 0
        while True:
            self._markers_wake.wait()
            self._markers_wake.clear()
            if self.markers_priority != applied:  # set by the composed twin in realtime
                applied = raise_thread_priority(self.markers_priority) or self.markers_priority
            due, self._markers_due = self._markers_due, None
            if self._markers_closed:
                return
            if due is not None:
                data = self._markers.build(*due)
                self._pub_markers(data)
                self.output.emit(contract.MARKERS, data)

    def destroy_node(self) -> None:
        """Stop the markers thread, then destroy the node."""
        self._markers_closed = True
        self._markers_wake.set()
        if self._markers_thread is not None:
            self._markers_thread.join(2.0)
        super().destroy_node()


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``micro_simulator`` as its own process, following a split-layout coordinator."""
    return run_scale_node(Role.MICRO, lambda role, **kw: MicroNode(
        role.stage, output=role.output, server=role, **kw), argv)


if __name__ == '__main__':
    sys.exit(main())
