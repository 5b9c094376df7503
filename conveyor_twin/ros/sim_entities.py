"""Conversions between the twin's entities and the messages of ``simulation_interfaces``.

Pure functions on message objects (the server, :mod:`conveyor_twin.ros.sim_interfaces`, calls
them): filters to an :class:`~conveyor_twin.coord.entities.EntityQuery`, entity states and
infos to messages, a spawn pose to (x, y, yaw) in the cell's frame.

The definitions of the ROS 2 releases (Jazzy, Kilted: 1.5 and 1.6) give ``SpawnEntity`` and
``Spawnable`` a ``uri`` (and ``resource_string``) of their own; later ones (2.x) a ``Resource``
in ``entity_resource``. :func:`resource_of` and :func:`spawnable` read and write both.
"""

import math
from typing import Optional, Tuple

from simulation_interfaces.msg import (Bounds, EntityCategory, EntityFilters, EntityInfo,
                                       EntityState, Result, Spawnable, TagsFilter)
from simulation_interfaces.srv import SpawnEntity

from conveyor_twin.cell.model import Cell
from conveyor_twin.coord import entities
from conveyor_twin.coord.entities import Entity, EntityQuery, Pose2D

#: The interface's category codes of the twin's categories.
CATEGORY_CODE = {entities.OBJECT: EntityCategory.CATEGORY_OBJECT,
                 entities.DYNAMIC: EntityCategory.CATEGORY_DYNAMIC_OBJECT,
                 entities.STATIC: EntityCategory.CATEGORY_STATIC_OBJECT}
_CATEGORY_OF_CODE = {code: name for name, code in CATEGORY_CODE.items()}
#: Largest |quaternion norm - 1| and roll/pitch component a spawn pose may have.
QUATERNION_TOLERANCE = 1e-6
#: Frames a spawn pose may be given in besides the cell's own ('' is the world frame).
WORLD_FRAMES = ('', 'world')


class Refused(Exception):
    """A request answered with a result code other than OK; ``code`` and the text say why."""

    def __init__(self, code: int, message: str) -> None:
        super().__init__(message)
        self.code = code

    def result(self) -> Result:
        """Return the interface's result of this refusal."""
        return Result(result=self.code, error_message=str(self))


def ok(message: str = '') -> Result:
    """Return an OK result."""
    return Result(result=Result.RESULT_OK, error_message=message)


def query_of(filters: EntityFilters) -> EntityQuery:
    """Return the query of an ``EntityFilters`` message.

    Categories the twin has no entities of (robot, human) match nothing. Bounds: a sphere
    (centre, radius in the x of the second point) or a box (two opposite corners), both taken
    in the cell's plane (z ignored) against each entity's footprint circle.

    :raises Refused: for a convex-hull bounds filter (FEATURE_UNSUPPORTED), malformed bounds or
        an unknown tag filter mode (OPERATION_FAILED), naming the field and value.
    """
    tags = filters.tags
    if tags.filter_mode not in (TagsFilter.FILTER_MODE_ANY, TagsFilter.FILTER_MODE_ALL):
        raise Refused(Result.RESULT_OPERATION_FAILED,
                      f'filters.tags.filter_mode {tags.filter_mode}: expected '
                      f'{TagsFilter.FILTER_MODE_ANY} (any) or {TagsFilter.FILTER_MODE_ALL} (all)')
    categories = tuple(_CATEGORY_OF_CODE.get(c.category, f'code {c.category}')
                       for c in filters.categories)
    circle, box = _bounds(filters.bounds)
    return EntityQuery(pattern=filters.filter, categories=categories, tags=tuple(tags.tags),
                       all_tags=tags.filter_mode == TagsFilter.FILTER_MODE_ALL,
                       circle=circle, box=box)


def _bounds(bounds: Bounds) -> Tuple[Optional[tuple], Optional[tuple]]:
    """Return (circle, box) of a bounds filter (None where not given)."""
    points = [(p.x, p.y, p.z) for p in bounds.points]
    if bounds.type == Bounds.TYPE_EMPTY:
        return None, None
    if not all(math.isfinite(v) for p in points for v in p):
        raise Refused(Result.RESULT_OPERATION_FAILED,
                      'filters.bounds.points: every coordinate must be a finite number')
    if bounds.type == Bounds.TYPE_SPHERE:
        if len(points) != 2 or points[1][0] < 0.0:
            raise Refused(Result.RESULT_OPERATION_FAILED,
                          f'filters.bounds: a sphere needs 2 points (centre, radius in x >= 0), '
                          f'got {points}')
        return (points[0][0], points[0][1], points[1][0]), None
    if bounds.type == Bounds.TYPE_BOX:
        if len(points) != 2:
            raise Refused(Result.RESULT_OPERATION_FAILED,
                          f'filters.bounds: a box needs 2 corners, got {len(points)} points')
        (ax, ay, _), (bx, by, _) = points
        return None, (min(ax, bx), min(ay, by), max(ax, bx), max(ay, by))
    if bounds.type == Bounds.TYPE_CONVEX_HULL:
        raise Refused(Result.RESULT_FEATURE_UNSUPPORTED,
                      'filters.bounds: convex hull bounds are not supported (supported: sphere, '
                      'box)')
    raise Refused(Result.RESULT_OPERATION_FAILED,
                  f'filters.bounds.type {bounds.type}: expected {Bounds.TYPE_EMPTY} (empty), '
                  f'{Bounds.TYPE_BOX} (box), {Bounds.TYPE_SPHERE} (sphere)')


def info_of(entity: Entity) -> EntityInfo:
    """Return the ``EntityInfo`` of an entity."""
    return EntityInfo(category=EntityCategory(category=CATEGORY_CODE[entity.category]),
                      description=entity.description, tags=list(entity.tags))


def state_of(pose: Pose2D, frame_id: str, time_ns: int) -> EntityState:
    """Return the ``EntityState`` of a pose in ``frame_id`` at sim time ``time_ns`` [ns]
    (acceleration zero: the twin does not keep it)."""
    msg = EntityState()
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(time_ns), 1_000_000_000)
    position, orientation = msg.pose.position, msg.pose.orientation
    position.x, position.y, position.z = pose.x, pose.y, pose.z
    orientation.z, orientation.w = math.sin(pose.yaw / 2), math.cos(pose.yaw / 2)
    msg.twist.linear.x, msg.twist.linear.y = pose.vx, pose.vy
    msg.twist.angular.z = pose.wz
    return msg


def yaw_of(x: float, y: float, z: float, w: float) -> float:
    """Return the yaw [rad] of a rotation about z given as a unit quaternion.

    :raises Refused: (INVALID_POSE) if it is not a unit quaternion or tilts the z axis.
    """
    values = (x, y, z, w)
    if not all(math.isfinite(v) for v in values):
        raise Refused(SpawnEntity.Response.INVALID_POSE,
                      f'initial_pose.pose.orientation {values}: not finite numbers')
    norm = math.sqrt(sum(v * v for v in values))
    if abs(norm - 1.0) > QUATERNION_TOLERANCE:
        raise Refused(SpawnEntity.Response.INVALID_POSE,
                      f'initial_pose.pose.orientation {values}: norm {norm:g}, expected a unit '
                      'quaternion')
    if abs(x) > QUATERNION_TOLERANCE or abs(y) > QUATERNION_TOLERANCE:
        raise Refused(SpawnEntity.Response.INVALID_POSE,
                      f'initial_pose.pose.orientation {values}: parts lie on the belt; allowed '
                      'is a rotation about z only (x = y = 0)')
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def resource_of(request) -> Tuple[str, str]:
    """Return (uri, resource_string) of a ``SpawnEntity`` request (either definition)."""
    resource = getattr(request, 'entity_resource', request)
    return resource.uri, resource.resource_string


def spawnable(uri: str, description: str) -> Spawnable:
    """Return a ``Spawnable`` of ``uri`` (either definition)."""
    msg = Spawnable(description=description)
    if hasattr(msg, 'entity_resource'):
        msg.entity_resource.uri = uri
    else:
        msg.uri = uri
    return msg


def spawn_pose(cell: Cell, pose_stamped) -> Tuple[float, float, float]:
    """Return (x [m], y [m], yaw [rad]) of a spawn request's ``initial_pose`` in the cell's
    frame; z is ignored (a part lies on the belt).

    :raises Refused: (INVALID_POSE) for another frame than the cell's ('' and 'world' are
        the cell's frame too) or an orientation that is not a rotation about z.
    """
    frame = pose_stamped.header.frame_id
    allowed = WORLD_FRAMES + (cell.settings.frame_id,)
    if frame not in allowed:
        raise Refused(SpawnEntity.Response.INVALID_POSE,
                      f'initial_pose.header.frame_id {frame!r}: unknown frame (allowed: '
                      + ', '.join(repr(f) for f in allowed) + ')')
    q = pose_stamped.pose.orientation
    yaw = yaw_of(q.x, q.y, q.z, q.w)
    p = pose_stamped.pose.position
    return float(p.x), float(p.y), yaw
