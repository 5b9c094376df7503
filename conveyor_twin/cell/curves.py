"""Geometry of a curved belt: an annular sector about a centre, moving as a rigid rotation.

Plain Python for consumers (drawing, spawn checks, region extents); the simulators build their
own tables from these values. Angles in rad, lengths in m.
"""

from dataclasses import dataclass
import math
from typing import Tuple

Point = Tuple[float, float]
Rect = Tuple[float, float, float, float]  # (x_min, y_min, x_max, y_max) [m]

#: Points within this distance [m] of a belt's edge count as on the belt (:meth:`Belt.contains`).
CONTAINS_TOLERANCE = 1e-9


@dataclass(frozen=True)
class BeltCurve:
    """The geometry of a curved belt: an annular sector about ``centre``.

    The surface moves as a rigid rotation about ``centre``; a part travels from ``start_angle``
    to ``end_angle`` in ``direction`` when the belt's speed is positive.

    :param centre: centre of the arcs [m].
    :param inner_radius: radius of the inner edge [m], > 0.
    :param outer_radius: radius of the outer edge [m], > ``inner_radius``.
    :param start_angle: polar angle of the entry edge about ``centre`` [rad].
    :param end_angle: polar angle of the exit edge about ``centre`` [rad].
    :param direction: +1 counter-clockwise, -1 clockwise (from start to end).
    :param guide_rails: the loader adds wall obstacles along both arcs, outside the surface.
    """

    centre: Point
    inner_radius: float
    outer_radius: float
    start_angle: float
    end_angle: float
    direction: int
    guide_rails: bool = False

    @property
    def sweep(self) -> float:
        """Signed angle travelled from ``start_angle`` to ``end_angle`` in ``direction`` [rad],
        0 < |sweep| <= 2 pi (end angles a whole turn apart, or closer than 1e-12 rad, sweep a
        whole turn)."""
        turn = 2.0 * math.pi
        travelled = (self.direction * (self.end_angle - self.start_angle)) % turn
        if travelled < 1e-12 or travelled > turn:
            travelled = turn
        return self.direction * travelled

    @property
    def centre_radius(self) -> float:
        """Radius of the centre line [m]: the mean of the two radii."""
        return 0.5 * (self.inner_radius + self.outer_radius)

    def point(self, radius: float, angle: float) -> Point:
        """Return the point at ``radius`` [m] and polar ``angle`` [rad] about ``centre``."""
        return (self.centre[0] + radius * math.cos(angle),
                self.centre[1] + radius * math.sin(angle))

    def arc(self, radius: float, max_chord_error: float) -> Tuple[Point, ...]:
        """Return points along the arc of ``radius`` from ``start_angle`` to ``end_angle``
        (both ends included), spaced so that no chord is farther than ``max_chord_error`` [m]
        from the arc."""
        sweep = self.sweep
        ratio = min(max_chord_error / radius, 1.0)
        step = 2.0 * math.acos(1.0 - ratio) if ratio < 1.0 else math.pi
        count = max(1, math.ceil(abs(sweep) / step - 1e-12))
        return tuple(self.point(radius, self.start_angle + sweep * i / count)
                     for i in range(count + 1))

    def angle_along(self, point: Point) -> float:
        """Return the unsigned angle [rad] travelled from ``start_angle`` in ``direction`` to
        the polar angle of ``point``, in [0, 2 pi)."""
        phi = math.atan2(point[1] - self.centre[1], point[0] - self.centre[0])
        return (self.direction * (phi - self.start_angle)) % (2.0 * math.pi)



def curve_contains(curve: BeltCurve, point: Point) -> bool:
    """Return True if ``point`` [m] lies on the annular sector, edges included (within
    :data:`CONTAINS_TOLERANCE`)."""
    tol = CONTAINS_TOLERANCE
    radius = math.hypot(point[0] - curve.centre[0], point[1] - curve.centre[1])
    if not curve.inner_radius - tol <= radius <= curve.outer_radius + tol:
        return False
    travelled = curve.angle_along(point)
    slack = tol / max(radius, tol)
    return travelled <= abs(curve.sweep) + slack or travelled >= 2.0 * math.pi - slack


def curve_outline(curve: BeltCurve, max_chord_error: float) -> Tuple[Point, ...]:
    """Return the sector's outline, counter-clockwise, first point not repeated: the outer arc
    and the inner arc as chords within ``max_chord_error`` [m] of the arcs."""
    outer = curve.arc(curve.outer_radius, max_chord_error)
    inner = curve.arc(curve.inner_radius, max_chord_error)
    polygon = outer + tuple(reversed(inner))
    return polygon if curve.direction > 0 else tuple(reversed(polygon))


def curve_bounding_box(curve: BeltCurve) -> Rect:
    """Return the exact axis-aligned bounding rectangle of the sector [m]: its four corners and
    the outer arc's points at 0, 90, 180 and 270 degrees that lie within the sweep."""
    a0, a1 = curve.start_angle, curve.start_angle + curve.sweep
    points = [curve.point(r, a) for r in (curve.inner_radius, curve.outer_radius)
              for a in (a0, a1)]
    for quarter in range(4):
        extreme = curve.point(curve.outer_radius, 0.5 * math.pi * quarter)
        if curve_contains(curve, extreme):
            points.append(extreme)
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    return (min(xs), min(ys), max(xs), max(ys))
