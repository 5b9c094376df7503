"""The twin's entities as a simulator interface names them, queries and deletes them (no ROS).

Every part of the micro scale is an entity named ``part_<id>`` (its id in ``parts``); the cell's
belts, actuators and light barriers are entities named ``belt_<name>``, ``actuator_<name>`` and
``light_barrier_<name>``. Parts held as density by the macro scale are not entities (they have
no pose of their own). Poses are in the cell's frame (``settings.frame_id``), 2D: x, y and yaw
about z, with z = 0 on the belt surface.

:func:`list_entities` lists them from a snapshot of the parts (:func:`snapshot_parts`),
:class:`EntityQuery` filters them (a regular expression on the name, categories, tags, an
overlap with a circle or a box), :func:`entity_state` gives an entity's pose and velocity and
:func:`delete_part` takes a part out of the micro scale as if it had left through a sink.
"""

from dataclasses import dataclass
import math
import re
from typing import Iterable, List, Optional, Sequence, Tuple

import numpy as np

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord.stages import MicroStage
from conveyor_twin.micro.state import PartsView

PART = 'part'
BELT = 'belt'
ACTUATOR = 'actuator'
LIGHT_BARRIER = 'light_barrier'
#: Entity kinds, in the order :func:`list_entities` lists them after the parts.
KINDS = (PART, BELT, ACTUATOR, LIGHT_BARRIER)

#: Categories (the interface's names): parts move, belts and light barriers stay where the
#: cell puts them, actuators move only along their axis.
DYNAMIC = 'dynamic_object'
STATIC = 'static_object'
OBJECT = 'object'
CATEGORY_OF_KIND = {PART: DYNAMIC, BELT: STATIC, ACTUATOR: OBJECT, LIGHT_BARRIER: STATIC}

_PART_NAME = re.compile(r'part_([1-9][0-9]*)\Z')


class EntityQueryError(ValueError):
    """A query the twin cannot answer; the text names the field, its value and what is allowed."""


@dataclass(frozen=True)
class Entity:
    """One entity of the twin.

    :param name: its unique name. :param kind: one of :data:`KINDS`.
    :param index: a part's id, else the index in the cell's list of its kind.
    :param category: one of :data:`DYNAMIC`, :data:`STATIC`, :data:`OBJECT`.
    :param tags: its kind and, for a part its type's name, for an actuator its kind.
    :param description: one line for a person.
    """

    name: str
    kind: str
    index: int
    category: str
    tags: Tuple[str, ...]
    description: str


@dataclass(frozen=True)
class Pose2D:
    """An entity's pose and velocity in the cell's frame.

    :param x: [m]. :param y: [m]. :param z: height of its reference point [m].
    :param yaw: [rad]. :param vx: [m/s]. :param vy: [m/s]. :param wz: [rad/s].
    """

    x: float
    y: float
    z: float
    yaw: float
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0


def snapshot_parts(stage: MicroStage) -> PartsView:
    """Copy the parts of ``stage`` now (call with the twin's lock held)."""
    return PartsView(*(np.array(a, copy=True) for a in stage.parts()))


def part_row(parts: PartsView, part_id: int) -> Optional[int]:
    """Return the row of part ``part_id`` in ``parts``, or None if it is not there."""
    hits = np.flatnonzero(parts.id == part_id)
    return int(hits[0]) if hits.size else None


def part_name(part_id: int) -> str:
    """Return the entity name of part ``part_id``."""
    return f'part_{int(part_id)}'


def part_id_of(name: str) -> Optional[int]:
    """Return the part id an entity name stands for (``part_<id>``), else None."""
    match = _PART_NAME.match(name)
    return int(match.group(1)) if match else None


def static_entities(cell: Cell) -> List[Entity]:
    """Return the cell's belts, actuators and light barriers as entities, in the cell's order."""
    out = [Entity(f'belt_{b.name}', BELT, i, STATIC, (BELT,),
                  f'belt {b.name!r}, {b.length:g} m x {b.width:g} m')
           for i, b in enumerate(cell.belts)]
    out += [Entity(f'actuator_{a.name}', ACTUATOR, i, OBJECT, (ACTUATOR, a.kind),
                   f'{a.kind} {a.name!r}') for i, a in enumerate(cell.actuators)]
    out += [Entity(f'light_barrier_{lb.name}', LIGHT_BARRIER, i, STATIC, (LIGHT_BARRIER,),
                   f'light barrier {lb.name!r} at {lb.height:g} m')
            for i, lb in enumerate(cell.light_barriers)]
    return out


def part_entities(cell: Cell, parts: PartsView) -> List[Entity]:
    """Return the micro parts as entities, ids ascending."""
    names = [p.name for p in cell.part_types]
    return [Entity(part_name(i), PART, int(i), DYNAMIC, (PART, names[t]),
                   f'{names[t]} part {int(i)}')
            for i, t in zip(parts.id.tolist(), parts.part_type.tolist())]


def list_entities(cell: Cell, parts: PartsView) -> List[Entity]:
    """Return every entity: the parts (ids ascending), then the belts, actuators and light
    barriers."""
    return part_entities(cell, parts) + static_entities(cell)


def find_entity(cell: Cell, parts: PartsView, name: str) -> Optional[Entity]:
    """Return the entity called ``name``, or None."""
    part_id = part_id_of(name)
    if part_id is not None:
        row = part_row(parts, part_id)
        if row is None:
            return None
        t = int(parts.part_type[row])
        type_name = cell.part_types[t].name
        return Entity(name, PART, part_id, DYNAMIC, (PART, type_name),
                      f'{type_name} part {part_id}')
    return next((e for e in static_entities(cell) if e.name == name), None)


def entity_state(cell: Cell, entity: Entity, parts: PartsView,
                 actuator_position: np.ndarray) -> Pose2D:
    """Return the pose and velocity of ``entity`` (a part: as the micro scale holds it; a belt:
    the centre of its surface, yaw along its running direction; a light barrier: the middle of
    its beam at its height, yaw along the beam; an actuator: a pusher's paddle centre, a
    stopper's blade or a transfer's footprint centre lifted by its position, a diverter's pivot
    with yaw along its arm).

    :param actuator_position: actual position of every actuator [m or rad].
    :raises KeyError: if a part is not held by the micro scale.
    """
    if entity.kind == PART:
        row = part_row(parts, entity.index)
        if row is None:
            raise KeyError(f'no part {entity.index} in the micro scale')
        return Pose2D(float(parts.x[row]), float(parts.y[row]), 0.0, float(parts.yaw[row]),
                      float(parts.vx[row]), float(parts.vy[row]), float(parts.wz[row]))
    if entity.kind == BELT:
        b = cell.belts[entity.index]
        if b.curve is not None:  # the middle of its centre line, yaw along its tangent there
            mx, my = b.centre_line(3)[1]
            vx, vy = b.surface_velocity((mx, my), 1.0)
            return Pose2D(mx, my, 0.0, math.atan2(vy, vx))
        return Pose2D((b.start[0] + b.end[0]) / 2, (b.start[1] + b.end[1]) / 2, 0.0, b.angle)
    if entity.kind == LIGHT_BARRIER:
        lb = cell.light_barriers[entity.index]
        return Pose2D((lb.start[0] + lb.end[0]) / 2, (lb.start[1] + lb.end[1]) / 2, lb.height,
                      math.atan2(lb.end[1] - lb.start[1], lb.end[0] - lb.start[0]))
    a = cell.actuators[entity.index]
    position = float(actuator_position[entity.index])
    heading = math.atan2(a.axis[1], a.axis[0])
    if a.kind == 'pusher':
        return Pose2D(a.base[0] + position * a.axis[0], a.base[1] + position * a.axis[1], 0.0,
                      heading)
    if a.kind in ('stopper', 'transfer'):
        return Pose2D(a.base[0], a.base[1], position, heading)
    return Pose2D(a.base[0], a.base[1], 0.0, heading + position)


def footprint_radius(cell: Cell, entity: Entity) -> float:
    """Return the radius of the circle about :func:`entity_state`'s (x, y) that holds the
    entity's footprint [m] (what a bounds filter overlaps)."""
    if entity.kind == PART:
        tags = entity.tags
        return next(p.bounding_radius for p in cell.part_types if p.name == tags[1])
    if entity.kind == BELT:
        b = cell.belts[entity.index]
        if b.curve is not None:  # the farthest outline vertex, plus the outline's chord error
            middle = b.centre_line(3)[1]
            return max(math.dist(middle, p) for p in b.outline(1e-3)) + 1e-3
        return math.hypot(b.length, b.width) / 2
    if entity.kind == LIGHT_BARRIER:
        lb = cell.light_barriers[entity.index]
        return math.hypot(lb.end[0] - lb.start[0], lb.end[1] - lb.start[1]) / 2
    a = cell.actuators[entity.index]
    if a.kind == 'diverter':  # the arm turns about the pivot
        return math.hypot(a.length, a.width / 2)
    return math.hypot(a.length, a.width) / 2


@dataclass(frozen=True)
class EntityQuery:
    """Filters on entities; each one given must hold (an empty query selects everything).

    :param pattern: a regular expression searched in the name ('' matches every name).
    :param categories: the entity's category is one of these (empty: any).
    :param tags: tags to look for (empty: no tag filter).
    :param all_tags: every tag of ``tags`` must be present (else any one).
    :param circle: (x, y, radius) [m]: the entity's footprint circle overlaps it.
    :param box: (x_min, y_min, x_max, y_max) [m]: the footprint circle overlaps this box.
    """

    pattern: str = ''
    categories: Tuple[str, ...] = ()
    tags: Tuple[str, ...] = ()
    all_tags: bool = False
    circle: Optional[Tuple[float, float, float]] = None
    box: Optional[Tuple[float, float, float, float]] = None

    def select(self, cell: Cell, entities: Iterable[Entity], parts: PartsView,
               actuator_position: np.ndarray) -> List[Entity]:
        """Return the entities that pass every filter, in their order.

        :raises EntityQueryError: if ``pattern`` is not a valid regular expression.
        """
        try:
            regex = re.compile(self.pattern) if self.pattern else None
        except re.error as exc:
            raise EntityQueryError(f'filters.filter {self.pattern!r} is not a valid regular '
                                   f'expression: {exc}') from None
        out = []
        for e in entities:
            if regex is not None and not regex.search(e.name):
                continue
            if self.categories and e.category not in self.categories:
                continue
            if self.tags and not self._tags_match(e.tags):
                continue
            if ((self.circle is not None or self.box is not None)
                    and not self._overlaps(cell, e, parts, actuator_position)):
                continue
            out.append(e)
        return out

    def _tags_match(self, tags: Sequence[str]) -> bool:
        have = [t in tags for t in self.tags]
        return all(have) if self.all_tags else any(have)

    def _overlaps(self, cell: Cell, e: Entity, parts: PartsView,
                  actuator_position: np.ndarray) -> bool:
        pose = entity_state(cell, e, parts, actuator_position)
        r = footprint_radius(cell, e)
        if self.circle is not None:
            cx, cy, cr = self.circle
            return math.hypot(pose.x - cx, pose.y - cy) <= cr + r
        x0, y0, x1, y1 = self.box
        dx = max(x0 - pose.x, 0.0, pose.x - x1)
        dy = max(y0 - pose.y, 0.0, pose.y - y1)
        return math.hypot(dx, dy) <= r


def delete_part(stage: MicroStage, part_id: int) -> None:
    """Take part ``part_id`` out of the micro scale now; it counts as left (``deleted``), so
    the part ledger stays balanced (call with the twin's lock held, between steps).

    :raises KeyError: if the micro scale does not hold it (nothing changed).
    """
    stage.sim.delete([part_id])
