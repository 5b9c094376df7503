"""Macro scale: part density on the belt as a conservation law (docs/models.md).

No ROS imports. :class:`MacroSim` is the entry point; :mod:`.reference` is the plain NumPy
reference the numba kernels are tested against.
"""

from conveyor_twin.macro.grid import Grid
from conveyor_twin.macro.solver import MacroSim

__all__ = ['Grid', 'MacroSim']
