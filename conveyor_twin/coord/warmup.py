"""Load the step path's numba kernels before real time starts, on a scratch copy of the cell.

numba compiles (or loads from its on-disk cache) a kernel the first time it is called with
given argument types. Loading costs 1-25 ms per kernel with the GIL held, so the first step of
a realtime run took 30-50 ms and every later first use (the first barrier edge, the first
actuator move, the first hand-over) cost another few ms: tens of overruns that say nothing
about the twin's speed. :func:`warm_up` runs the paths once on a throwaway :class:`Twin` of
the same cell (its own stages, nothing shared with the run), so the run itself never waits
for a kernel.
"""

from typing import Sequence

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.assembly import build_twin

# Steps of the scratch twin: enough for every actuator to move and a part under each
# barrier to produce its edges.
WARM_UP_STEPS = 60
# Steps after each forced switch of an ``auto`` zone (all tiles macro, then all micro).
SWITCH_STEPS = 10


def _beam_midpoints(cell: Cell) -> Sequence[tuple]:
    return [(0.5 * (b.start[0] + b.end[0]), 0.5 * (b.start[1] + b.end[1]))
            for b in cell.light_barriers]


def warm_up(cell: Cell, seed: int, steps: int = WARM_UP_STEPS) -> int:
    """Step a scratch twin of ``cell`` so every per-step kernel is loaded; return its steps.

    One part of each type is placed at every light barrier's beam (edges, event drain), every
    actuator is sent to the far end of its range, and every belt runs at its maximum speed.
    Placements that overlap something are skipped. Then every ``auto`` zone is switched to
    macro and back (:data:`SWITCH_STEPS` steps each way). Nothing of the scratch twin is kept.
    """
    scratch = build_twin(cell, seed=seed)
    twin, micro = scratch.twin, scratch.micro
    for type_index in range(len(cell.part_types)):
        for x, y in _beam_midpoints(cell):
            try:
                micro.spawn(type_index, np.array([x]), np.array([y]), np.zeros(1))
            except ValueError:
                pass
    for index, actuator in enumerate(cell.actuators):
        low, high = actuator.position_range
        far = high if abs(high - actuator.initial_position) >= abs(
            low - actuator.initial_position) else low
        twin.actuation.set_actuator_target(index, far)
    for index, belt in enumerate(cell.belts):
        twin.actuation.set_belt_target(index, belt.max_speed)
    for _ in range(steps):
        _step(twin, micro)
    return steps + _switch_auto_zones(scratch, SWITCH_STEPS if steps else 0)


def _step(twin, micro) -> None:
    twin.step(1)
    micro.edges()
    micro.barrier_blocked()
    micro.barrier_edge_count()
    micro.parts()


def _switch_auto_zones(scratch, steps: int) -> int:
    """Turn every tile of each ``auto`` zone macro (the parts in it are captured), step, turn
    them micro again (the density is released as parts), step: the hand-over's kernels load
    here, not at the run's first switch. Return the steps taken."""
    taken = 0
    coupling = scratch.coupling
    for region in getattr(coupling, 'regions', ()) if steps else ():
        tiles = region.tiles
        if tiles is None:
            continue
        for macro in (np.ones_like(tiles.macro), np.zeros_like(tiles.macro)):
            coupling.force_tiles(region.sim.zone.name, macro)
            for _ in range(steps):
                _step(scratch.twin, scratch.micro)
            taken += steps
    return taken
