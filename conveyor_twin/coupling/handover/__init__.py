"""Compiled kernels of the micro <-> macro hand-over (no ROS imports, allocation-free).

Every kernel works on one macro grid: density ``rho`` ``(ny, nx)`` [parts/m^2], origin
``(ox, oy)`` [m], cell edge ``h`` [m], an ``active`` mask ``(ny, nx)`` (1: the cell is simulated
macro now) and the grid's ``solid`` mask (1: obstacle or engaged actuator). One module per step
of the hand-over:

- :mod:`.deposit`: micro parts entering a macro tile become density;
- :mod:`.hold_back`: density flowing into micro tiles waits where the micro parts leave no
  room, and out of sensor windows;
- :mod:`.gather`: the thin remainder waiting in front of a window is gathered into whole parts;
- :mod:`.release`: wherever a window of density holds a whole part, a micro part is placed;
- :mod:`.buckets`: the micro parts near a release spot;
- :mod:`.outflow`: density leaving through boundary faces and sinks;
- :mod:`.reference`: plain-Python versions of the release and the gathering, for the tests.

The kernels are re-exported here, so ``handover.<kernel>`` names any of them.
"""

from conveyor_twin.coupling.handover.buckets import (bucket_add, bucket_parts, BUCKET_SLACK,
                                                     BUCKETS, near_parts)
from conveyor_twin.coupling.handover.deposit import (capture_mask, deposit_disc, deposit_push,
                                                     DEPOSIT_SAMPLES)
from conveyor_twin.coupling.handover.gather import (border_cells, gather_fronts, GATHER_SLACK,
                                                    STALE_CELLS, STALE_MASS)
from conveyor_twin.coupling.handover.hold_back import (entrance_depth, ENTRANCE_FILL, hold_back,
                                                       hold_back_runs, inactive_runs,
                                                       push_out_of_window, push_upstream,
                                                       upstream_of)
from conveyor_twin.coupling.handover.outflow import (accumulate_faces, side_max, take_cells,
                                                     take_mask)
from conveyor_twin.coupling.handover.release import (micro_blocks, next_uniform,
                                                     RELEASE_ROUND_OFF, release_windows,
                                                     window_candidate, window_subtract)

__all__ = [
    'accumulate_faces', 'border_cells', 'bucket_add', 'bucket_parts', 'BUCKET_SLACK', 'BUCKETS',
    'capture_mask', 'deposit_disc', 'deposit_push', 'DEPOSIT_SAMPLES', 'entrance_depth',
    'ENTRANCE_FILL',
    'gather_fronts', 'GATHER_SLACK', 'hold_back', 'hold_back_runs', 'inactive_runs',
    'micro_blocks', 'near_parts', 'next_uniform', 'push_out_of_window', 'push_upstream',
    'RELEASE_ROUND_OFF', 'release_windows', 'side_max', 'STALE_CELLS', 'STALE_MASS',
    'take_cells', 'take_mask', 'upstream_of', 'window_candidate', 'window_subtract',
]
