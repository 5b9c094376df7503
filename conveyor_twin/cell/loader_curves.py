"""Read the curved-belt and transfer-unit keys of a cell file; generate guide rails.

A curved belt is given by its ``curve`` mapping (angles in degrees in the file, rad in the
model); its ``start``, ``end`` and ``width`` follow from the curve and may not be given.
Guide rails are wall obstacles along both arcs, just outside the surface.
"""

import math
from typing import Dict, List, Sequence, Tuple

from conveyor_twin.cell.errors import CellError
from conveyor_twin.cell.model import Belt, BeltCurve, Obstacle, ObstacleKind, Point
from conveyor_twin.cell.reader import KeyReader

#: Full thickness of a generated guide rail [m].
RAIL_THICKNESS = 0.005
#: Largest distance [m] between a guide rail's face and the arc it follows (the surface edge).
RAIL_CHORD_ERROR = 1e-4
#: Gap [m] left between a rail's face and the surface edge at the rail's vertices.
RAIL_GAP = 1e-6
#: Smallest inner radius [m] of a curved belt with guide rails (the inner rail must fit).
MIN_RAILED_INNER_RADIUS = 2.0 * RAIL_THICKNESS
#: Largest radius of a curve [m].
MAX_RADIUS = 100.0
#: Smallest sweep [deg] of a curve.
MIN_SWEEP_DEG = 1e-6
_DIRECTIONS = {'ccw': 1, 'cw': -1}


def read_curve(r: KeyReader) -> Tuple[BeltCurve, Point, Point, float]:
    """Read the ``curve`` mapping of the belt reader ``r``.

    :returns: the curve, the centre-line start and end points [m] and the width [m].
    :raises CellError: if the belt also gives start, end or width, or a curve key is invalid.
    """
    for key in ('start', 'end', 'width'):
        if key in r.data:
            r.seen.add(key)
            raise r.fail(key, r.data[key], 'no start, end or width on a curved belt (they '
                         'follow from its curve: centre, radii and angles)')
    c = r.section('curve', required=True)
    centre = c.point('centre')
    inner = c.number('inner_radius', low=0.0, high=MAX_RADIUS, low_open=True)
    outer = c.number('outer_radius', low=0.0, high=MAX_RADIUS, low_open=True)
    if outer <= inner:
        raise c.fail('outer_radius', outer, f'a radius in ({inner:g}, {MAX_RADIUS:g}] [m] '
                     f'(above inner_radius {inner:g})')
    start = c.number('start_angle', low=-360.0, high=360.0)
    end = c.number('end_angle', low=-360.0, high=360.0)
    direction = _DIRECTIONS[c.string('direction', choices=tuple(_DIRECTIONS))]
    rails = c.boolean('guide_rails', False)
    c.done()
    sweep = _sweep_deg(c, start, end, direction)
    if rails and inner < MIN_RAILED_INNER_RADIUS:
        raise c.fail('inner_radius', inner, f'at least {MIN_RAILED_INNER_RADIUS:g} m with '
                     'guide_rails: true (the inner rail lies inside the inner edge)')
    curve = BeltCurve(centre=centre, inner_radius=inner, outer_radius=outer,
                      start_angle=math.radians(start),
                      end_angle=math.radians(start + direction * sweep),
                      direction=direction, guide_rails=rails)
    centre_line = curve.centre_radius
    return (curve, curve.point(centre_line, curve.start_angle),
            curve.point(centre_line, curve.end_angle), outer - inner)


def _sweep_deg(c: KeyReader, start: float, end: float, direction: int) -> float:
    """Return the unsigned sweep [deg] from ``start`` to ``end`` in ``direction``, (0, 360]."""
    expected = (f'an end angle whose sweep from start_angle {start:g} deg going '
                f"{'ccw' if direction > 0 else 'cw'} is in (0, 360] deg")
    travelled = direction * (end - start)
    if abs(travelled) > 360.0:
        raise c.fail('end_angle', end, expected + ' (at most 360 deg from start_angle)')
    sweep = travelled % 360.0
    if sweep == 0.0 and travelled != 0.0:
        sweep = 360.0
    if sweep < MIN_SWEEP_DEG:
        raise c.fail('end_angle', end, expected + ' (not zero)')
    return sweep


def guide_rails(belts: Sequence[Belt]) -> Tuple[Obstacle, ...]:
    """Return the wall obstacles ``<belt>_rail_inner`` and ``<belt>_rail_outer`` of every
    curved belt with ``guide_rails``: polylines of thickness :data:`RAIL_THICKNESS` whose
    faces lie outside the surface, within :data:`RAIL_CHORD_ERROR` of its arcs."""
    half = 0.5 * RAIL_THICKNESS
    chord = RAIL_CHORD_ERROR - RAIL_GAP
    rails: List[Obstacle] = []
    for belt in belts:
        c = belt.curve
        if c is None or not c.guide_rails:
            continue
        # the outer rail's chords cut inward by up to `chord`: its vertices sit that much out
        outer = c.arc(c.outer_radius + half + RAIL_CHORD_ERROR, chord)
        # the inner rail's chords bow away from the surface: its vertices touch the gap
        inner = c.arc(c.inner_radius - half - RAIL_GAP, chord)
        for side, points in (('inner', inner), ('outer', outer)):
            rails.append(Obstacle(name=f'{belt.name}_rail_{side}', kind=ObstacleKind.WALL,
                                  points=points, thickness=RAIL_THICKNESS))
    return tuple(rails)


def check_rail_names(file: str, obstacles: Sequence[Obstacle],
                     rails: Sequence[Obstacle]) -> None:
    """Raise a CellError if an obstacle of the file takes the name of a generated guide rail."""
    generated: Dict[str, int] = {rail.name: 1 for rail in rails}
    for k, obstacle in enumerate(obstacles):
        if obstacle.name in generated:
            raise CellError(file, f'obstacles[{k}].name', obstacle.name,
                            'a name other than a generated guide rail\'s (<belt>_rail_inner, '
                            '<belt>_rail_outer of a curved belt with guide_rails: true)')
