"""The plant description: cells placed in a plant frame and the transfer links between them.

Frame ``plant``: x, y in metres, yaw in radians (REP-103), as the cells' own frames. Every cell
of a plant steps with the same step; a link's delay is a whole number of steps, at least one.
"""

from dataclasses import dataclass
from typing import Optional, Tuple

from conveyor_twin.cell.model import Cell, Rect

#: Plant-wide part ids: cell ``k`` (in plant order) numbers its parts from ``k * ID_RANGE + 1``.
ID_BITS = 24
ID_RANGE = 1 << ID_BITS
#: Most cells in a plant (ids are uint32: 256 ranges of 2^24).
MAX_CELLS = 256


@dataclass(frozen=True)
class Placement:
    """Pose of a cell's frame in the plant frame: x, y [m], yaw [rad]."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0


@dataclass(frozen=True)
class PlantCell:
    """One cell of the plant.

    :param name: unique within the plant.
    :param file: the cell file as given (resolved against the plant file's folder).
    :param namespace: ROS namespace of the cell's node (its topics move under it).
    :param cell: the validated cell as the plant runs it: sinks that feed links removed (the
        link takes those parts; see :class:`LinkEnd`).
    :param seed: random seed of the cell's sources.
    :param placement: where the cell's frame lies in the plant frame.
    :param index: position in the plant's list (its id range, see :data:`ID_RANGE`).
    """

    name: str
    file: str
    namespace: str
    cell: Cell
    seed: int
    placement: Placement
    index: int


@dataclass(frozen=True)
class LinkEnd:
    """Where a link takes parts out of a cell or puts them in.

    Exactly one of ``sink``, ``belt`` or ``region`` is set. Exit (``from``): a sink's region
    or the end of a belt. Entry (``to``): the start of a belt or a region.

    :param cell: name of the cell.
    :param sink: exit through this sink of the cell file (the plant removes it from the cell).
    :param belt: exit at this belt's end, or entry at its start.
    :param region: entry rectangle (x_min, y_min, x_max, y_max) [m] in the cell frame.
    """

    cell: str
    sink: Optional[str] = None
    belt: Optional[str] = None
    region: Optional[Rect] = None


@dataclass(frozen=True)
class EndFrame:
    """A link end in its cell: frame origin (x, y) [m] and yaw [rad], and the rectangle in
    that frame where parts leave or enter: x in [x0, x1], |y| <= half_width [m]
    (:mod:`conveyor_twin.plant.geometry`)."""

    x: float
    y: float
    yaw: float
    x0: float
    x1: float
    half_width: float


@dataclass(frozen=True)
class Link:
    """A transfer from one cell's exit to another cell's entry.

    :param name: unique within the plant; the name of its ROS topics.
    :param source: the exit (``from`` in the file).
    :param target: the entry (``to`` in the file).
    :param delay_steps: transport delay [steps], >= 1: a part that left in step ``k`` enters
        in step ``k + delay_steps`` at the earliest (later if the entry is occupied).
    :param capacity: most parts in the link (in transit and waiting); while it holds that
        many the exit takes no part and parts queue upstream. 0: unlimited.
    :param type_map: for each part type index of the source cell, the index of the type of
        the same name in the target cell.
    :param exit: the exit's frame and rectangle in the source cell.
    :param entry: the entry's frame and rectangle in the target cell.
    """

    name: str
    source: LinkEnd
    target: LinkEnd
    delay_steps: int
    capacity: int
    type_map: Tuple[int, ...]
    exit: EndFrame
    entry: EndFrame


@dataclass(frozen=True)
class Plant:
    """A whole validated plant.

    :param step: the step of every cell [s].
    """

    source_file: str
    name: str
    namespace: str
    step: float
    cells: Tuple[PlantCell, ...]
    links: Tuple[Link, ...]

    def cell(self, name: str) -> PlantCell:
        """Return the cell ``name``; raise KeyError if unknown."""
        for c in self.cells:
            if c.name == name:
                return c
        raise KeyError(name)

    def links_from(self, name: str) -> Tuple[Link, ...]:
        """Return the links whose exit is in cell ``name``, in plant order."""
        return tuple(k for k in self.links if k.source.cell == name)

    def links_to(self, name: str) -> Tuple[Link, ...]:
        """Return the links whose entry is in cell ``name``, in plant order."""
        return tuple(k for k in self.links if k.target.cell == name)

    @property
    def min_delay(self) -> int:
        """The shortest link delay [steps] (the plant's lookahead); 1 without links."""
        return min((k.delay_steps for k in self.links), default=1)
