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

from conveyor_twin_msgs.msg import LightBarrierEdge, LightBarrierStates, PartStates
from visualization_msgs.msg import MarkerArray

from conveyor_twin.coord import codec
from conveyor_twin.coord.mirror import MicroSide
from conveyor_twin.coord.runner import raise_thread_priority
from conveyor_twin.coord.stages import MicroStage
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.ros.markers import CellMarkers
from conveyor_twin.ros import coupling
from conveyor_twin.ros.qos import EDGE_QOS, raw_publish, SLOW_QOS, STREAM_QOS
from conveyor_twin.ros.scale_node import ScaleNode
from conveyor_twin.ros.standalone import run_scale_node
from conveyor_twin.wire import cdr


class MicroNode(ScaleNode):
    """Publish ``parts``, ``light_barriers``, ``light_barrier_edges`` and part ``markers``.

    :param stage: the micro stage.
    :param side: split layout, cells with ``macro``/``auto`` zones: the micro half of the
        hand-over (the assembly's ``micro_side``); the node then exchanges it with the macro
        node every step.
    """

    def __init__(self, stage: MicroStage, *, side: Optional[MicroSide] = None,
                 **kwargs) -> None:
        super().__init__('micro_simulator', stage, codec.MICRO_ROLE, **kwargs)
        cell = stage.cell
        frame = cell.settings.frame_id
        self._frame = frame
        self._barrier_names = [b.name for b in cell.light_barriers]
        self._parts = cdr.PartStatesEncoder(frame, capacity=cell.micro.capacity)
        self._barriers = cdr.LightBarrierStatesEncoder(frame, self._barrier_names)
        self._markers = CellMarkers(cell)
        self.parts_pub = self.create_publisher(PartStates, 'parts', STREAM_QOS)
        self.barrier_pub = self.create_publisher(LightBarrierStates, 'light_barriers',
                                                 STREAM_QOS)
        self.edge_pub = self.create_publisher(LightBarrierEdge, 'light_barrier_edges',
                                              EDGE_QOS)
        self.markers_pub = self.create_publisher(MarkerArray, 'markers', SLOW_QOS)
        self._pub_parts = raw_publish(self.parts_pub, self.get_logger())
        self._pub_barriers = raw_publish(self.barrier_pub, self.get_logger())
        self._pub_edge = raw_publish(self.edge_pub, self.get_logger())
        self._pub_markers = raw_publish(self.markers_pub, self.get_logger())
        self._markers_due = None
        self.markers_priority = 0  # SCHED_FIFO priority of the markers thread (0: normal)
        self._markers_closed = False
        self._markers_wake = threading.Event()
        self._markers_thread = None
        if self.markers_every:
            self._markers_thread = threading.Thread(target=self._markers_loop,
                                                    name='conveyor_twin_markers', daemon=True)
            self._markers_thread.start()
        self._side = side  # the scale hand-over's micro half (split layout, coupled cells)
        if self.remote and side is not None:
            self.open_exchange(coupling.MICRO_STATE_TOPIC, coupling.EDITS_TOPIC, self._on_edits)
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
        """Publish the parts, barrier states and any barrier edges of the step just taken."""
        stage = self.stage
        ids, part_type, x, y, yaw, vx, vy, wz = stage.parts()
        self._pub_parts(self._parts.encode(inp.time_ns, inp.step, ids, part_type, x, y, yaw,
                                           vx, vy, wz))
        blocked, edge_count = stage.barrier_blocked(), stage.barrier_edge_count()
        self._pub_barriers(self._barriers.encode(inp.time_ns, inp.step, blocked, edge_count))
        barrier, rising, time_ns, part_id = stage.edges()
        for i in range(len(barrier)):
            self._pub_edge(cdr.encode_light_barrier_edge(
                int(time_ns[i]), self._frame, self._barrier_names[barrier[i]], bool(rising[i]),
                int(part_id[i])))
        if self.markers_every and inp.step % self.markers_every == 0:
            # copies (a few us) here; the ~0.5 ms of building happens off the stepping thread
            self._markers_due = (inp.time_ns, part_type.copy(), x.copy(), y.copy(),
                                 blocked.copy(), inp.actuator_position.copy())
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
                self._pub_markers(self._markers.build(*due))

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


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``micro_simulator`` as its own process, following a split-layout coordinator."""
    return run_scale_node('micro', lambda a, **kw: MicroNode(
        a.micro, side=a.micro_side, counters=a.micro_counters, reset=a.reset_scales, **kw), argv)


if __name__ == '__main__':
    sys.exit(main())
