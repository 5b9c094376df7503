"""``macro_simulator``: publishes the density grid of every macro zone each step.

As its own process (split layout) with a cell whose zones are ``macro``/``auto``, it also runs
the scale hand-over each step on a mirror of the micro state the micro node sends, and sends the
edits back (:mod:`conveyor_twin.coord.mirror`); its counters then carry the cell's ledger.
"""

import sys
from typing import Dict, List, Optional

from conveyor_twin import contract
from conveyor_twin.coord import codec
from conveyor_twin.coord.mirror import MacroSide
from conveyor_twin.coord.stages import MacroStage
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import MacroOutput
from conveyor_twin.ros import coupling
from conveyor_twin.ros.scale_node import ScaleNode
from conveyor_twin.ros.standalone import run_scale_node
from conveyor_twin.ros.stream_publisher import StreamPublisher


class MacroNode(ScaleNode):
    """Publish one ``density`` message per macro zone and step.

    A sink of the twin's frames: it publishes the macro part of every frame of ``output``.
    Without ``output`` (split layout) the node makes the output of its own stage and builds a
    frame when its step is done.

    :param stage: the macro stage.
    :param side: split layout, cells with ``macro``/``auto`` zones: the hand-over on a mirror
        of the micro state (the assembly's ``macro_side``); the node then exchanges it with
        the micro node every step.
    :param output: the twin's output to subscribe to (composed: shared by the three nodes).
    """

    def __init__(self, stage: MacroStage, *, side: Optional[MacroSide] = None,
                 output: Optional[TwinOutput] = None, **kwargs) -> None:
        super().__init__('macro_simulator', stage, codec.MACRO_ROLE, **kwargs)
        self.output = output if output is not None else TwinOutput([MacroOutput(stage)])
        self.streams = StreamPublisher(self, (contract.DENSITY,))
        self.density_pub = self.streams.publishers[contract.DENSITY]
        self._side = side  # the hand-over on a micro mirror (split)
        self._states: Dict[int, memoryview] = {}  # micro states by step, arrived early
        if self.remote and side is not None:
            self.open_exchange(coupling.EDITS_TOPIC, coupling.MICRO_STATE_TOPIC,
                               self._on_micro_state)
        self.output.subscribe(self.streams)
        self.serve_coordinator()

    def exchange(self, inp: StepInput) -> None:
        """Hand over once the micro state of the step has arrived."""
        self._couple()

    def _on_micro_state(self, data: bytes) -> None:
        step, body = codec.parse_stamped(codec.from_cdr(data))
        self._states[step] = body
        self._couple()

    def _couple(self) -> None:
        """Run the hand-over of the pending step if its micro state is here; finish it."""
        inp = self._pending
        if inp is None or inp.step not in self._states:
            return
        state = self._states.pop(inp.step)
        if self._states:
            stale = sorted(self._states)
            self.get_logger().error(f'micro states of steps {stale} unused; dropped')
            self._states.clear()
        self._pending = None
        reply = self._side.couple(inp, state)
        self.send_exchange(codec.to_cdr(codec.stamped(inp.step, reply)))
        self.finish_step(inp)

    def reset_stage(self, cell, seed: int) -> None:
        """Restart the grids and the hand-over; drop micro states that arrived early."""
        super().reset_stage(cell, seed)
        self._states.clear()

    def publish_step(self, inp: StepInput) -> None:
        """Split layout: build this process's frame of the step just taken (and publish it)."""
        self.output.on_step(inp)

    def spawn_reply(self, body: bytes) -> bytes:
        """Parts are spawned by the micro scale; the macro node only acknowledges."""
        return b''


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``macro_simulator`` as its own process, following a split-layout coordinator."""
    return run_scale_node('macro', lambda a, **kw: MacroNode(
        a.macro, side=a.macro_side, counters=a.macro_counters, reset=a.reset_scales, **kw), argv)


if __name__ == '__main__':
    sys.exit(main())
