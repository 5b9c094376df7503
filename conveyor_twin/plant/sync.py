"""Conservative synchronisation of the cells of a plant: how far a cell may run.

A part that leaves a cell in step ``k`` enters the next cell in step ``k + d`` at the earliest
(``d``: the link's delay, >= 1 step). So a cell may compute step ``s`` once every upstream
neighbour has completed step ``s - d`` of the link between them: no part can arrive for a step
it has computed already (Chandy and Misra's conservative rule with the delay as lookahead).
A link with a capacity also feeds back: its exit takes a part in step ``s`` only if the link
holds fewer than the capacity, counting the insertions of the downstream cell up to step
``s - d``; so the upstream cell may compute step ``s`` once the downstream cell has completed
step ``s - d``, or once the downstream cell's run has finished (its final batch: it inserts
nothing more, so every later step's room is known). Cells never wait for more than that, and
since ``d >= 1`` the cell that is furthest behind can always step: the rule never deadlocks.

The exception for a finished peer matters after a restart: a restarted cell counts its steps
from 0 again while its neighbours count on, so the cells of a link no longer end at the same
step of the link's count. A restarted upstream cell would otherwise wait forever for a
downstream cell that has completed its last step (the cells of a fixed-duration run).

The same rule drives the cells stepped in one process (:mod:`conveyor_twin.plant.runner`) and
the cells in processes of their own (:mod:`conveyor_twin.ros.plant_cell_node`); what a cell computes
depends only on what its neighbours computed up to ``s - d``, never on when it arrived, which
is why both give the same bits.
"""

from typing import Iterable

from conveyor_twin.plant.link import LinkEntry, LinkExit

#: No neighbour limits the cell.
UNBOUNDED = 1 << 62


def horizon(entries: Iterable[LinkEntry], exits: Iterable[LinkExit]) -> int:
    """Return the last step the cell may compute with what its neighbours reported."""
    limit = UNBOUNDED
    for e in entries:
        limit = min(limit, e.peer_through + e.delay)
    for x in exits:
        if x.capacity and not x.peer_final:
            limit = min(limit, x.peer_through + x.delay)
    return limit


def may_step(step: int, entries: Iterable[LinkEntry], exits: Iterable[LinkExit]) -> bool:
    """Return True if the cell may compute ``step``."""
    return step <= horizon(entries, exits)
