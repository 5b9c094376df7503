"""Micro scale: every part a planar rigid body on the belts (Hoher et al., docs/models.md).

:class:`~conveyor_twin.micro.sim.MicroSim` is the entry point; the kernels live in the other
modules. Imports numpy and numba only (no ROS).
"""

from conveyor_twin.micro.errors import (CapacityError, MicroError, SpawnBoundsError,
                                        SpawnOverlapError)
from conveyor_twin.micro.sim import EdgeEvents, MicroSim
from conveyor_twin.micro.state import PartsView

__all__ = ['CapacityError', 'EdgeEvents', 'MicroError', 'MicroSim', 'PartsView',
           'SpawnBoundsError', 'SpawnOverlapError']
