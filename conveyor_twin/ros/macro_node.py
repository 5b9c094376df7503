"""``macro_simulator``: publishes the density grid of every macro zone each step.

As its own process (split layout) it serves the macro role
(:class:`~conveyor_twin.split.roles.MacroRole`): with a cell whose zones are ``macro``/``auto``,
that role also runs the scale hand-over each step on a mirror of the micro state the micro
node sends, and sends the edits back (:mod:`conveyor_twin.split.mirror`); its counters then
carry the cell's ledger.
"""

import sys
from typing import List, Optional

from conveyor_twin import contract
from conveyor_twin.coord.layout import Role
from conveyor_twin.coord.stages import MacroStage
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.ros.scale_node import ScaleNode
from conveyor_twin.ros.standalone import run_scale_node
from conveyor_twin.ros.stream_publisher import StreamPublisher


class MacroNode(ScaleNode):
    """Publish one ``density`` message per macro zone and step.

    A sink of the twin's frames: it publishes the macro part of every frame of ``output``.

    :param stage: the macro stage.
    :param output: the output to subscribe to (composed: shared by the three nodes; split: the
        macro role's, which builds a frame when its step is done).
    :param kwargs: as :class:`ScaleNode` (``server``: the split layout's macro role).
    """

    def __init__(self, stage: MacroStage, *, output: TwinOutput, **kwargs) -> None:
        super().__init__('macro_simulator', stage, **kwargs)
        self.output = output
        self.streams = StreamPublisher(self, contract.frame_streams(contract.Producer.MACRO))
        self.density_pub = self.streams.publishers[contract.DENSITY]
        self.output.subscribe(self.streams)
        self.serve_coordinator()


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``macro_simulator`` as its own process, following a split-layout coordinator."""
    return run_scale_node(Role.MACRO, lambda role, **kw: MacroNode(
        role.stage, output=role.output, server=role, **kw), argv)


if __name__ == '__main__':
    sys.exit(main())
