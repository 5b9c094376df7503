"""Micro scale: every part a planar rigid body on the belts (seed 000, section 3).

:class:`~conveyor_twin.micro.sim.MicroSim` is the entry point; the kernels live in the other
modules. Imports numpy and numba only (no ROS).
"""

from conveyor_twin.micro._cache import drop_stale_caches
drop_stale_caches()
from conveyor_twin.micro.errors import (CapacityError, MicroError,  # noqa: E402
                                        SpawnOverlapError)
from conveyor_twin.micro.sim import EdgeEvents, MicroSim  # noqa: E402
from conveyor_twin.micro.state import PartsView  # noqa: E402

__all__ = ['CapacityError', 'EdgeEvents', 'MicroError', 'MicroSim', 'PartsView',
           'SpawnOverlapError']
