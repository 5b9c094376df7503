"""What a ``spawn_parts`` or a ``reset`` request may contain (no ROS imports).

The coordinator node only converts the service request into these calls and answers with the
result: a :class:`RequestRejected` names what is wrong and is answered as ``success = false``
with its text; nothing is applied.
"""

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from conveyor_twin.cell import CellError, load_cell
from conveyor_twin.cell.model import Cell


class RequestRejected(ValueError):
    """A spawn or reset request the twin does not apply; the text says why."""


@dataclass(frozen=True)
class SpawnRequest:
    """A checked ``spawn_parts`` request: parts of one type at finite poses.

    :param part_type: name of the part type.
    :param type_index: its wire index in the cell.
    :param x: x of every part [m]. :param y: y [m]. :param yaw: yaw [rad].
    """

    part_type: str
    type_index: int
    x: np.ndarray
    y: np.ndarray
    yaw: np.ndarray

    @property
    def count(self) -> int:
        """Number of parts requested."""
        return int(self.x.size)

    def placed_message(self) -> str:
        """Return the answer of a spawn that placed every part."""
        return f'placed {self.count} {self.part_type} part(s)'


def check_spawn(cell: Cell, part_type: str, x: Sequence[float], y: Sequence[float],
                yaw: Sequence[float]) -> SpawnRequest:
    """Check a spawn request against ``cell``.

    :param part_type: name of a part type of the cell.
    :param x: x of every part [m]. :param y: y of every part [m].
    :param yaw: yaw of every part [rad]; empty: 0 for every part.
    :raises RequestRejected: for an unknown part type, arrays of different or zero length, or a
        pose that is not a finite number.
    """
    n = len(x)
    try:
        type_index = cell.part_type_index(part_type)
    except KeyError:
        raise RequestRejected(f'unknown part_type {part_type!r} (known: '
                              + ', '.join(p.name for p in cell.part_types) + ')') from None
    xs, ys = np.asarray(x, float), np.asarray(y, float)
    yaws = np.asarray(yaw, float) if len(yaw) else np.zeros(n)
    if not (len(y) == n and len(yaws) == n) or n == 0:
        raise RequestRejected(f'x, y and yaw must have the same non-zero length '
                              f'(got {n}, {len(y)}, {len(yaw)})')
    if not (np.isfinite(xs).all() and np.isfinite(ys).all() and np.isfinite(yaws).all()):
        raise RequestRejected('poses must be finite numbers')
    return SpawnRequest(part_type, type_index, xs, ys, yaws)


def same_interface(a: Cell, b: Cell) -> bool:
    """Return True if ``a`` and ``b`` publish the same arrays: the same belts, actuators, light
    barriers and zones, by name and in order."""
    def names(cell: Cell):
        return ([x.name for x in cell.belts], [x.name for x in cell.actuators],
                [x.name for x in cell.light_barriers], [z.name for z in cell.zones])
    return names(a) == names(b)


def check_reset(current: Cell, cell_file: str) -> Cell:
    """Return the cell a reset request restarts with.

    :param current: the cell running now.
    :param cell_file: another cell YAML; empty: ``current``.
    :raises RequestRejected: if the file is not a valid cell (the loader's message naming file,
        key and value), or its belts, actuators, light barriers or zones differ from
        ``current``'s (the published arrays would change).
    """
    try:
        cell = load_cell(cell_file) if cell_file else current
    except CellError as exc:
        raise RequestRejected(str(exc)) from None
    if cell is not current and not same_interface(cell, current):
        raise RequestRejected('reset to a cell with other belts, actuators or light barriers '
                              'needs a restart of the twin (the published arrays would change)')
    return cell


def reset_message(seed: int, cell: Cell) -> str:
    """Return the answer of a reset that restarted with ``seed`` and ``cell``."""
    return f'reset to step 0 with seed {seed} ({cell.settings.name})'
