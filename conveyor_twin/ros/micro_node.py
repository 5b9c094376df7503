"""``micro_simulator``: publishes every micro part, the light barriers and their edges.

Composed, its stage is stepped by the coordinator in the same process; as its own process
(``ros2 run conveyor_twin micro_simulator`` or ``python -m conveyor_twin.ros.micro_node``) it
follows the coordinator's step inputs over the coupling topic. For a cell with ``macro``/``auto``
zones it then sends its state after each step to the macro node, which runs the hand-over, and
replays the returned edits before it publishes (:mod:`conveyor_twin.coord.mirror`).
"""

import sys
import threading
from typing import List, Optional


from conveyor_twin import contract
from conveyor_twin.coord import codec
from conveyor_twin.coord.mirror import MicroSide
from conveyor_twin.coord.runner import raise_thread_priority
from conveyor_twin.coord.stages import MicroStage
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.faults.material import holds_part
from conveyor_twin.output.frame import Frame
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.markers import CellMarkers
from conveyor_twin.output.producers import MicroOutput
from conveyor_twin.ros import coupling
from conveyor_twin.ros.endpoints import create_publisher
from conveyor_twin.ros.qos import raw_publish
from conveyor_twin.ros.scale_node import ScaleNode
from conveyor_twin.ros.standalone import run_scale_node
from conveyor_twin.ros.stream_publisher import StreamPublisher

#: The streams this node publishes from the frames (markers it builds itself).
STREAMS = (contract.PARTS, contract.LIGHT_BARRIERS, contract.LIGHT_BARRIER_EDGES)
#: Name of the markers thread (and of its failure in the twin's health).
MARKERS_THREAD = 'markers thread'


class MicroNode(ScaleNode):
    """Publish ``parts``, ``light_barriers``, ``light_barrier_edges`` and part ``markers``.

    A sink of the twin's frames: it publishes the micro part of every frame of ``output``.
    Without ``output`` (split layout) the node makes the output of its own stage and builds a
    frame when its step is done.

    :param stage: the micro stage.
    :param side: split layout, cells with ``macro``/``auto`` zones: the micro half of the
        hand-over (the assembly's ``micro_side``); the node then exchanges it with the macro
        node every step.
    :param output: the twin's output to subscribe to (composed: shared by the three nodes).
    """

    def __init__(self, stage: MicroStage, *, side: Optional[MicroSide] = None,
                 output: Optional[TwinOutput] = None, **kwargs) -> None:
        super().__init__('micro_simulator', stage, codec.MICRO_ROLE, **kwargs)
        cell = stage.cell
        self.output = output if output is not None else TwinOutput([MicroOutput(stage)])
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
        self._side = side  # the scale hand-over's micro half (split layout, coupled cells)
        if self.remote and side is not None:
            self.open_exchange(coupling.MICRO_STATE_TOPIC, coupling.EDITS_TOPIC, self._on_edits)
        self.output.subscribe(self.streams)
        if self.markers_every:
            self.output.subscribe(self)  # on_frame: hands the due markers' state over
        self.serve_coordinator()

    def exchange(self, inp: StepInput) -> None:
        """Send the step's micro state to the macro node (its edits finish the step)."""
        self.send_exchange(codec.to_cdr(codec.stamped(inp.step, self._side.state_bytes())))

    def _on_edits(self, data: bytes) -> None:
        """Replay the macro node's hand-over edits of the pending step, then finish it."""
        step, body = codec.parse_stamped(codec.from_cdr(data))
        inp = self._pending
        if inp is None or step != inp.step:
            pending = None if inp is None else inp.step
            self.get_logger().error(f'hand-over edits of step {step} while step {pending} '
                                    'is pending; ignored')
            return
        self._pending = None
        self._side.apply(body)
        self.finish_step(inp)

    def publish_step(self, inp: StepInput) -> None:
        """Split layout: build this process's frame of the step just taken (and publish it)."""
        self.output.on_step(inp)

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

    def spawn_reply(self, body: bytes) -> bytes:
        """Place parts for a split-layout spawn request: ``E`` + message, or ``I`` + ids."""
        type_index, x, y, yaw = codec.parse_spawn(body)
        try:
            ids = self.stage.spawn(type_index, x, y, yaw)
        except ValueError as exc:
            return codec.spawn_error(str(exc))
        return codec.spawn_reply(ids)

    def part_reply(self, body: bytes) -> bytes:
        """Answer whether the micro scale holds a part of the queried id now (``part_jam``)."""
        return codec.part_reply(holds_part(self.stage.sim, codec.parse_part_query(body)))


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``micro_simulator`` as its own process, following a split-layout coordinator."""
    return run_scale_node('micro', lambda a, **kw: MicroNode(
        a.micro, side=a.micro_side, counters=a.micro_counters, reset=a.reset_scales, **kw), argv)


if __name__ == '__main__':
    sys.exit(main())
