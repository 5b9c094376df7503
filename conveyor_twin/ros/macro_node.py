"""``macro_simulator``: publishes the density grid of every macro zone each step."""

import sys
from typing import List, Optional

from conveyor_twin_msgs.msg import DensityGrid

from conveyor_twin.coord.stages import MacroStage
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.ros.qos import raw_publish, STREAM_QOS
from conveyor_twin.ros.scale_node import MACRO_ROLE, ScaleNode
from conveyor_twin.wire import cdr


class MacroNode(ScaleNode):
    """Publish one ``density`` message per macro zone and step."""

    def __init__(self, stage: MacroStage, **kwargs) -> None:
        super().__init__('macro_simulator', stage, MACRO_ROLE, **kwargs)
        frame = stage.cell.settings.frame_id
        self._encoders = [cdr.DensityGridEncoder(frame, g.zone.name, g.origin_x, g.origin_y,
                                                 g.resolution, g.nx, g.ny)
                          for g in stage.grids]
        self.density_pub = self.create_publisher(DensityGrid, 'density', STREAM_QOS)
        self._pub_density = raw_publish(self.density_pub, self.get_logger())

    def publish_step(self, inp: StepInput) -> None:
        """Publish every macro zone's density for the step just taken."""
        for encoder, grid in zip(self._encoders, self.stage.grids):
            self._pub_density(encoder.encode(inp.time_ns, inp.step, grid.density,
                                             grid.total_parts()))

    def spawn_reply(self, body: bytes) -> bytes:
        """Parts are spawned by the micro scale; the macro node only acknowledges."""
        return b''


def main(argv: Optional[List[str]] = None) -> int:
    """Run ``macro_simulator`` as its own process, following a split-layout coordinator."""
    from conveyor_twin.ros.standalone import run_scale_node
    return run_scale_node(MacroNode, MacroStage, argv)


if __name__ == '__main__':
    sys.exit(main())
