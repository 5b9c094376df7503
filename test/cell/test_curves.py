"""Curved belts in the cell format: parsing, validation messages, the geometry helpers against
analytic values, the generated guide rails, the L-shaped example, and straight cells as before."""

import copy
import dataclasses
import hashlib
import json
import math
from pathlib import Path
import random
from typing import Any, Dict, List, Optional, Sequence, Tuple

import pytest

from conveyor_twin.cell import CellError, cell_from_mapping, load_cell
from conveyor_twin.cell.loader_curves import RAIL_CHORD_ERROR, RAIL_THICKNESS
from conveyor_twin.cell.model import Belt, BeltCurve, ObstacleKind
from conveyor_twin.cell.summary import summarize
from conveyor_twin.cli import main as cli_main

EXAMPLES = Path(__file__).resolve().parents[2] / 'conveyor_twin' / 'cell' / 'examples'
Point = Tuple[float, float]

#: Straight infeed along +x, a quarter turn to the left, a straight outfeed along +y.
DOC: Dict[str, Any] = {
    'cell': {'name': 'bend'},
    'belts': [
        {'name': 'infeed', 'start': [0.0, 0.0], 'end': [2.0, 0.0], 'width': 0.4, 'speed': 0.5},
        {'name': 'bend', 'speed': 0.5,
         'curve': {'centre': [2.0, 0.6], 'inner_radius': 0.4, 'outer_radius': 0.8,
                   'start_angle': -90, 'end_angle': 0, 'direction': 'ccw',
                   'guide_rails': True}},
        {'name': 'outfeed', 'start': [2.6, 0.6], 'end': [2.6, 2.6], 'width': 0.4, 'speed': 0.5},
    ],
    'part_types': [{'name': 'can', 'shape': 'disc', 'radius': 0.03, 'height': 0.1,
                    'mass': 0.3}],
}


def _doc(**curve: Any) -> Dict[str, Any]:
    """Return DOC with the bend's curve keys replaced (a value None removes the key)."""
    doc = copy.deepcopy(DOC)
    keys = doc['belts'][1]['curve']
    for key, value in curve.items():
        if value is None:
            keys.pop(key, None)
        else:
            keys[key] = value
    return doc


def _curved(centre: Point = (0.0, 0.0), inner: float = 1.0, outer: float = 2.0,
            start: float = 0.0, end: float = 90.0, direction: str = 'ccw',
            speed: float = 1.0) -> Belt:
    doc = {'cell': {'name': 'c'}, 'part_types': DOC['part_types'],
           'belts': [{'name': 'c', 'speed': speed, 'curve': {
               'centre': list(centre), 'inner_radius': inner, 'outer_radius': outer,
               'start_angle': start, 'end_angle': end, 'direction': direction}}]}
    return cell_from_mapping(doc, 'c.yaml').belts[0]


def _error(doc: Dict[str, Any]) -> str:
    with pytest.raises(CellError) as info:
        cell_from_mapping(doc, 'bend.yaml')
    return str(info.value)


# --- parsing ----------------------------------------------------------------------------------

def test_a_curved_belt_derives_its_centre_line_ends_width_and_length() -> None:
    cell = cell_from_mapping(DOC, 'bend.yaml')
    bend = cell.belts[1]
    c = bend.curve
    assert c == BeltCurve(centre=(2.0, 0.6), inner_radius=0.4, outer_radius=0.8,
                          start_angle=math.radians(-90), end_angle=0.0, direction=1,
                          guide_rails=True)
    assert c.sweep == pytest.approx(math.pi / 2) and c.centre_radius == pytest.approx(0.6)
    assert bend.start == pytest.approx((2.0, 0.0), abs=1e-12)   # the infeed's end
    assert bend.end == pytest.approx((2.6, 0.6), abs=1e-12)     # the outfeed's start
    assert bend.width == pytest.approx(0.4)
    assert bend.length == pytest.approx(0.6 * math.pi / 2)
    assert cell.belts[0].curve is None and cell.belts[2].curve is None


@pytest.mark.parametrize('start, end, direction, sweep_deg', [
    (0, 90, 'ccw', 90), (0, 90, 'cw', -270), (90, 0, 'cw', -90), (90, 0, 'ccw', 270),
    (0, 360, 'ccw', 360), (360, 0, 'cw', -360), (-180, 180, 'ccw', 360), (170, -170, 'ccw', 20),
    (-90, 0, 'ccw', 90), (10, 10.5, 'ccw', 0.5), (0, -360, 'ccw', 360),
])
def test_the_sweep_runs_from_start_to_end_angle_in_direction(start: float, end: float,
                                                            direction: str,
                                                            sweep_deg: float) -> None:
    c = _curved(start=start, end=end, direction=direction).curve
    assert c.sweep == pytest.approx(math.radians(sweep_deg), abs=1e-12)
    assert c.end_angle - c.start_angle == pytest.approx(c.sweep, abs=1e-12)
    assert c.start_angle == pytest.approx(math.radians(start))
    # the stored end angle is the file's, modulo a turn
    turns = (c.end_angle - math.radians(end)) / (2 * math.pi)
    assert turns == pytest.approx(round(turns), abs=1e-12)


def test_the_model_sweep_takes_angles_a_turn_apart_as_a_full_turn() -> None:
    for end in (2 * math.pi, 2 * math.pi + 1e-15, 2 * math.pi - 1e-15, 4 * math.pi):
        curve = BeltCurve((0.0, 0.0), 1.0, 2.0, 0.0, end, 1)
        assert curve.sweep == pytest.approx(2 * math.pi)
    assert BeltCurve((0.0, 0.0), 1.0, 2.0, 0.0, 2 * math.pi, -1).sweep == pytest.approx(
        -2 * math.pi)


def test_guide_rails_are_off_by_default() -> None:
    cell = cell_from_mapping(_doc(guide_rails=None), 'bend.yaml')
    assert cell.belts[1].curve.guide_rails is False and cell.obstacles == ()


# --- validation -------------------------------------------------------------------------------

@pytest.mark.parametrize('key', ['start', 'end', 'width'])
def test_a_curved_belt_given_start_end_or_width_is_refused(key: str) -> None:
    doc = copy.deepcopy(DOC)
    doc['belts'][1][key] = 0.4 if key == 'width' else [2.0, 0.0]
    msg = _error(doc)
    assert msg.startswith(f'bend.yaml: belts[1].{key}: got ')
    assert 'expected no start, end or width on a curved belt' in msg


@pytest.mark.parametrize('curve, path, expected', [
    (dict(inner_radius=0.0), 'inner_radius: got 0',
     'expected a finite number in (0, 100]'),
    (dict(inner_radius=-0.4), 'inner_radius: got -0.4', 'in (0, 100]'),
    (dict(inner_radius='wide'), "inner_radius: got 'wide'", 'in (0, 100]'),
    (dict(outer_radius=0.4), 'outer_radius: got 0.4',
     'expected a radius in (0.4, 100] [m] (above inner_radius 0.4)'),
    (dict(outer_radius=0.3), 'outer_radius: got 0.3', 'above inner_radius 0.4'),
    (dict(outer_radius=101.0), 'outer_radius: got 101', 'a finite number in (0, 100]'),
    (dict(start_angle=400), 'start_angle: got 400', 'a finite number in [-360, 360]'),
    (dict(end_angle=-361), 'end_angle: got -361', 'a finite number in [-360, 360]'),
    (dict(end_angle=-90), 'end_angle: got -90',
     'expected an end angle whose sweep from start_angle -90 deg going ccw is in (0, 360] '
     'deg (not zero)'),
    (dict(start_angle=-270, end_angle=180), 'end_angle: got 180',
     'is in (0, 360] deg (at most 360 deg from start_angle)'),
    (dict(direction='left'), "direction: got 'left'", "expected one of 'ccw', 'cw'"),
    (dict(direction=None), 'direction: got None', 'this required key to be present'),
    (dict(centre=None), 'centre: got None', 'this required key to be present'),
    (dict(centre=[2.0]), 'centre: got [2.0]', 'a point [x, y]'),
    (dict(guide_rails='yes'), "guide_rails: got 'yes'", 'expected true or false'),
    (dict(guide_rails=True, inner_radius=0.005), 'inner_radius: got 0.005',
     'expected at least 0.01 m with guide_rails: true'),
    (dict(radius=0.6), 'radius: got 0.6', 'no such key here; known keys: centre, direction'),
])
def test_every_curve_error_names_file_key_value_and_range(curve: Dict[str, Any], path: str,
                                                         expected: str) -> None:
    msg = _error(_doc(**curve))
    assert msg.startswith(f'bend.yaml: belts[1].curve.{path}'), msg
    assert expected in msg, msg


def test_a_curve_that_is_not_a_mapping_is_refused() -> None:
    doc = copy.deepcopy(DOC)
    doc['belts'][1]['curve'] = [2.0, 0.6]
    assert _error(doc).startswith('bend.yaml: belts[1].curve: got [2.0, 0.6]; expected a '
                                  'mapping of keys to values')


def test_an_obstacle_named_like_a_generated_rail_is_refused() -> None:
    doc = copy.deepcopy(DOC)
    doc['obstacles'] = [{'name': 'bend_rail_outer', 'kind': 'wall',
                         'points': [[0.0, 1.0], [1.0, 1.0]]}]
    msg = _error(doc)
    assert msg.startswith("bend.yaml: obstacles[0].name: got 'bend_rail_outer'; expected a name "
                          "other than a generated guide rail's")


# --- geometry helpers -------------------------------------------------------------------------

def _polar(belt: Belt, radius: float, angle: float) -> Point:
    c = belt.curve
    return (c.centre[0] + radius * math.cos(angle), c.centre[1] + radius * math.sin(angle))


@pytest.mark.parametrize('direction', ['ccw', 'cw'])
def test_contains_holds_the_boundary_and_nothing_beyond(direction: str) -> None:
    belt = _curved(centre=(1.0, -2.0), inner=0.5, outer=0.9, start=30, end=120,
                   direction=direction)
    c = belt.curve
    a0, a1 = c.start_angle, c.start_angle + c.sweep
    inside_angles = [a0, a1, 0.5 * (a0 + a1), a0 + 0.1 * c.sweep]
    for angle in inside_angles:
        for radius in (0.5, 0.9, 0.7):
            assert belt.contains(_polar(belt, radius, angle)), (radius, angle)
        assert not belt.contains(_polar(belt, 0.5 - 1e-6, angle))
        assert not belt.contains(_polar(belt, 0.9 + 1e-6, angle))
    step = math.copysign(1e-5, c.sweep)
    for radius in (0.5, 0.7, 0.9):
        assert not belt.contains(_polar(belt, radius, a0 - step))
        assert not belt.contains(_polar(belt, radius, a1 + step))
    assert not belt.contains(c.centre)
    # the other side of the annulus is not part of the sector
    assert not belt.contains(_polar(belt, 0.7, 0.5 * (a0 + a1) + math.pi))


def test_contains_of_a_straight_belt_holds_its_corners_and_edges() -> None:
    belt = cell_from_mapping(DOC, 'bend.yaml').belts[0]
    for corner in belt.corners():
        assert belt.contains(corner)
    assert belt.contains((1.0, 0.2)) and belt.contains((0.0, 0.0)) and belt.contains((2.0, 0.1))
    for outside in ((1.0, 0.2 + 1e-6), (-1e-6, 0.0), (2.0 + 1e-6, 0.0)):
        assert not belt.contains(outside)


def test_a_full_turn_holds_the_whole_annulus() -> None:
    belt = _curved(inner=1.0, outer=2.0, start=-135, end=225, direction='ccw')
    assert belt.curve.sweep == pytest.approx(2 * math.pi)
    assert belt.length == pytest.approx(1.5 * 2 * math.pi)
    for k in range(36):
        assert belt.contains(_polar(belt, 1.5, k * math.pi / 18))
    assert belt.bounding_box() == pytest.approx((-2.0, -2.0, 2.0, 2.0))


@pytest.mark.parametrize('direction, sign', [('ccw', 1.0), ('cw', -1.0)])
def test_surface_velocity_is_omega_cross_r(direction: str, sign: float) -> None:
    speed = 0.8
    belt = _curved(centre=(0.5, 0.25), inner=0.3, outer=0.7, start=0, end=90,
                   direction=direction, speed=speed)
    omega = sign * speed / 0.5
    rng = random.Random(7)
    for _ in range(50):
        r, angle = rng.uniform(0.3, 0.7), rng.uniform(-math.pi, math.pi)
        x, y = _polar(belt, r, angle)
        vx, vy = belt.surface_velocity((x, y), speed)
        assert vx == pytest.approx(-omega * (y - 0.25), abs=1e-12)
        assert vy == pytest.approx(omega * (x - 0.5), abs=1e-12)
        assert math.hypot(vx, vy) == pytest.approx(abs(omega) * r)       # |v| = |omega| r
        assert vx * (x - 0.5) + vy * (y - 0.25) == pytest.approx(0.0, abs=1e-12)  # tangent
    # the centre line moves at the belt speed
    for point in belt.centre_line(7):
        assert math.hypot(*belt.surface_velocity(point, speed)) == pytest.approx(speed)


def test_the_curve_carries_parts_on_from_the_infeed_into_the_outfeed() -> None:
    infeed, bend, outfeed = cell_from_mapping(DOC, 'bend.yaml').belts
    assert bend.surface_velocity(bend.start, 0.5) == pytest.approx(
        infeed.surface_velocity(infeed.end, 0.5), abs=1e-12)
    assert bend.surface_velocity(bend.end, 0.5) == pytest.approx(
        outfeed.surface_velocity(outfeed.start, 0.5), abs=1e-12)
    assert infeed.surface_velocity((1.0, 0.1), -0.5) == (-0.5, -0.0)


def _signed_area(polygon: Sequence[Point]) -> float:
    n = len(polygon)
    return 0.5 * sum(polygon[i][0] * polygon[(i + 1) % n][1]
                     - polygon[(i + 1) % n][0] * polygon[i][1] for i in range(n))


def _radius(point: Point, centre: Point) -> float:
    return math.hypot(point[0] - centre[0], point[1] - centre[1])


@pytest.mark.parametrize('direction', ['ccw', 'cw'])
@pytest.mark.parametrize('error', [1e-3, 1e-4, 1e-5])
def test_the_outline_is_ccw_and_within_the_chord_error_of_the_arcs(direction: str,
                                                                  error: float) -> None:
    belt = _curved(centre=(0.2, 0.1), inner=0.4, outer=0.8, start=-90, end=30,
                   direction=direction)
    c = belt.curve
    polygon = belt.outline(error)
    assert len(set(polygon)) == len(polygon)   # the first point is not repeated
    exact = 0.5 * abs(c.sweep) * (0.8 ** 2 - 0.4 ** 2)
    area = _signed_area(polygon)
    assert area > 0.0   # counter-clockwise
    assert area == pytest.approx(exact, rel=4 * error / 0.4)
    n = len(polygon)
    for i in range(n):
        p, q = polygon[i], polygon[(i + 1) % n]
        rp, rq = _radius(p, c.centre), _radius(q, c.centre)
        assert min(abs(rp - 0.4), abs(rp - 0.8)) < 1e-12   # every vertex on an arc
        if abs(rp - rq) < 1e-9:   # a chord of an arc: its middle within the error
            middle = ((p[0] + q[0]) / 2, (p[1] + q[1]) / 2)
            assert 0.0 <= rp - _radius(middle, c.centre) <= error * (1 + 1e-9)
    # finer outlines have more vertices
    assert len(belt.outline(error / 10)) > n


def test_the_outline_of_a_straight_belt_is_its_corners() -> None:
    belt = cell_from_mapping(DOC, 'bend.yaml').belts[0]
    assert belt.outline() == belt.corners()
    assert _signed_area(belt.outline()) == pytest.approx(2.0 * 0.4)


@pytest.mark.parametrize('direction', ['ccw', 'cw'])
def test_the_centre_line_runs_from_start_to_end_with_the_belts_length(direction: str) -> None:
    belt = _curved(centre=(-1.0, 2.0), inner=0.2, outer=0.6, start=200, end=20,
                   direction=direction)
    c = belt.curve
    points = belt.centre_line(2001)
    assert points[0] == pytest.approx(belt.start, abs=1e-12)
    assert points[-1] == pytest.approx(belt.end, abs=1e-12)
    assert all(abs(_radius(p, c.centre) - 0.4) < 1e-12 for p in points)
    polyline = sum(math.dist(points[i], points[i + 1]) for i in range(len(points) - 1))
    assert polyline == pytest.approx(belt.length, rel=1e-6)
    assert belt.length == pytest.approx(0.4 * math.pi)
    with pytest.raises(ValueError, match="belt 'c': centre_line needs n >= 2 points"):
        belt.centre_line(1)


def test_the_centre_line_of_a_straight_belt_is_its_segment() -> None:
    belt = cell_from_mapping(DOC, 'bend.yaml').belts[2]
    assert belt.centre_line(2) == (belt.start, belt.end)
    assert belt.centre_line(5)[2] == pytest.approx((2.6, 1.6))


@pytest.mark.parametrize('method', ['direction', 'angle', 'corners'])
def test_straight_only_geometry_of_a_curved_belt_raises_naming_the_belt(method: str) -> None:
    bend = cell_from_mapping(DOC, 'bend.yaml').belts[1]
    with pytest.raises(ValueError, match=r"belt 'bend' is curved: it has no .*; use contains\(\)"):
        value = getattr(bend, method)
        if callable(value):
            value()


def test_the_bounding_box_of_a_sector_is_exact() -> None:
    cell = cell_from_mapping(DOC, 'bend.yaml')
    assert cell.belts[1].bounding_box() == pytest.approx((2.0, -0.2, 2.8, 0.6), abs=1e-12)
    assert cell.bounds == pytest.approx((0.0, -0.2, 2.8, 2.6), abs=1e-12)
    assert cell.zones[0].region == pytest.approx(cell.bounds)  # the default zone
    half = _curved(inner=1.0, outer=2.0, start=0, end=180)
    assert half.bounding_box() == pytest.approx((-2.0, 0.0, 2.0, 2.0), abs=1e-12)
    rng = random.Random(3)
    for _ in range(30):
        start = rng.uniform(-360, 360)
        belt = _curved(centre=(rng.uniform(-5, 5), rng.uniform(-5, 5)), inner=0.5, outer=1.5,
                       start=start, end=max(-360.0, min(360.0, start + rng.uniform(-300, 300))),
                       direction=rng.choice(['ccw', 'cw']))
        x0, y0, x1, y1 = belt.bounding_box()
        outline = belt.outline(1e-6)
        assert min(p[0] for p in outline) == pytest.approx(x0, abs=2e-6)
        assert max(p[0] for p in outline) == pytest.approx(x1, abs=2e-6)
        assert min(p[1] for p in outline) == pytest.approx(y0, abs=2e-6)
        assert max(p[1] for p in outline) == pytest.approx(y1, abs=2e-6)


# --- guide rails ------------------------------------------------------------------------------

def _segment_distance(point: Point, a: Point, b: Point) -> float:
    vx, vy = b[0] - a[0], b[1] - a[1]
    t = ((point[0] - a[0]) * vx + (point[1] - a[1]) * vy) / (vx * vx + vy * vy)
    t = min(1.0, max(0.0, t))
    return math.hypot(point[0] - a[0] - t * vx, point[1] - a[1] - t * vy)


def _off_by_turns(angle: float) -> float:
    """Return how far ``angle`` [rad] is from a whole number of turns [rad]."""
    rest = angle % (2 * math.pi)
    return min(rest, 2 * math.pi - rest)


def _rails(doc: Dict[str, Any]) -> Tuple[Belt, Dict[str, Any]]:
    cell = cell_from_mapping(doc, 'bend.yaml')
    return cell.belts[1], {o.name: o for o in cell.obstacles}


@pytest.mark.parametrize('curve', [
    {}, dict(direction='cw', start_angle=0, end_angle=-90), dict(inner_radius=0.01),
    dict(start_angle=0, end_angle=360), dict(outer_radius=30.0),
])
def test_guide_rails_lie_outside_the_surface_within_a_tenth_of_a_millimetre(
        curve: Dict[str, Any]) -> None:
    belt, rails = _rails(_doc(**curve))
    c = belt.curve
    assert sorted(rails) == ['bend_rail_inner', 'bend_rail_outer']
    half = 0.5 * RAIL_THICKNESS
    for side, edge in (('inner', c.inner_radius), ('outer', c.outer_radius)):
        rail = rails[f'bend_rail_{side}']
        assert rail.kind == ObstacleKind.WALL and rail.thickness == RAIL_THICKNESS == 0.005
        points = rail.points
        # from the start angle to the end angle
        assert _off_by_turns(c.angle_along(points[0])) < 1e-9
        assert _off_by_turns(c.angle_along(points[-1]) - abs(c.sweep)) < 1e-9
        # the face towards the surface: nearest and farthest distance from the edge
        faces: List[float] = []
        for a, b in zip(points, points[1:]):
            near = _segment_distance(c.centre, a, b)
            far = max(_radius(a, c.centre), _radius(b, c.centre))
            if side == 'outer':  # the inner face of the outer rail: radius - half
                faces += [near - half, far - half]
            else:                # the outer face of the inner rail: radius + half
                faces += [near + half, far + half]
        if side == 'outer':
            assert min(faces) >= edge, 'the outer rail reaches onto the surface'
            assert max(faces) <= edge + RAIL_CHORD_ERROR + 1e-12
        else:
            assert max(faces) <= edge, 'the inner rail reaches onto the surface'
            assert min(faces) >= edge - RAIL_CHORD_ERROR - 1e-12
        assert RAIL_CHORD_ERROR == 1e-4


def test_the_rails_follow_the_file_obstacles_and_a_straight_cell_has_none() -> None:
    doc = copy.deepcopy(DOC)
    doc['obstacles'] = [{'name': 'wall', 'kind': 'wall', 'points': [[0.0, 0.21], [2.0, 0.21]]}]
    names = [o.name for o in cell_from_mapping(doc, 'bend.yaml').obstacles]
    assert names == ['wall', 'bend_rail_inner', 'bend_rail_outer']


# --- summary, the example cell, straight cells ------------------------------------------------

def test_the_summary_names_the_curve() -> None:
    text = summarize(cell_from_mapping(DOC, 'bend.yaml'))
    assert 'bend 0.942478 m x 0.4 m (90 deg ccw curve, radius 0.4..0.8 m, guide rails) at ' \
           '0.5 m/s' in text
    assert 'extent x 0..2.8 m, y -0.2..2.6 m' in text


def test_the_l_line_example_is_an_l_with_a_railed_curve_sensors_and_one_zone(capsys) -> None:
    path = EXAMPLES / 'l_line.yaml'
    cell = load_cell(path)
    infeed, bend, outfeed = cell.belts
    assert infeed.curve is None and outfeed.curve is None and bend.curve.guide_rails
    assert bend.curve.sweep == pytest.approx(math.pi / 2)
    # the curve joins both straights, with their width and running direction
    assert bend.start == pytest.approx(infeed.end, abs=1e-12)
    assert bend.end == pytest.approx(outfeed.start, abs=1e-12)
    assert bend.width == infeed.width == outfeed.width
    assert bend.surface_velocity(bend.start, 1.0) == pytest.approx(infeed.direction, abs=1e-12)
    assert bend.surface_velocity(bend.end, 1.0) == pytest.approx(outfeed.direction, abs=1e-12)
    names = [o.name for o in cell.obstacles]
    assert names[-2:] == ['bend_rail_inner', 'bend_rail_outer']
    (source,), (sink,) = cell.sources, cell.sinks
    x0, y0, x1, y1 = source.region
    assert infeed.contains((x0, y0)) and infeed.contains((x1, y1))
    assert sink.region[1] < outfeed.end[1] < sink.region[3]
    before, after = cell.light_barriers
    assert infeed.contains(before.start) and infeed.contains(before.end)
    assert outfeed.contains(after.start) and outfeed.contains(after.end)
    (zone,) = cell.zones
    zx0, zy0, zx1, zy1 = zone.region
    bx0, by0, bx1, by1 = cell.bounds
    assert zx0 <= bx0 and zy0 <= by0 and zx1 >= bx1 and zy1 >= by1
    assert zone.policy == 'auto'
    assert cli_main(['validate', str(path)]) == 0
    assert "Cell 'l_line'" in capsys.readouterr().out


#: sha256 (16 hex digits) of each shipped straight cell's model without the fields added for
#: curves and transfer units (``curve``, ``surface_speed``, ``force_limit``) and the contact
#: sweeps (``contact_sweeps*``, ``contact_tolerance``, at their defaults), as loaded before they
#: existed: straight cells load exactly as before.
STRAIGHT_CELLS = {
    None: '1ef353f40d37dbc8',
    'bench_micro.yaml': '1fc4c13a66784750',
    'examples/merge.yaml': '816e98f0b89459ad',
    'examples/multiscale.yaml': 'a629cb84c076a6d2',
    'examples/sorting.yaml': 'ec5b1295a8987456',
}
NEW_FIELDS = {'curve', 'surface_speed', 'force_limit', 'contact_sweeps', 'contact_sweeps_max',
              'contact_sweep_budget', 'contact_tolerance'}


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.name not in NEW_FIELDS}
    if isinstance(value, (tuple, list)):
        return [_plain(item) for item in value]
    return value


@pytest.mark.parametrize('name', list(STRAIGHT_CELLS))
def test_straight_cells_load_exactly_as_before(name: Optional[str]) -> None:
    cell = load_cell(EXAMPLES.parent / name if name else None)
    assert all(b.curve is None for b in cell.belts)
    assert all(a.surface_speed == 0.0 for a in cell.actuators)
    assert (cell.micro.contact_sweeps, cell.micro.contact_sweep_budget,
            cell.micro.contact_tolerance) == (16, 200_000, 3e-4)
    plain = _plain(cell)
    plain['source_file'] = ''
    if name is None:
        # the default cell's collision operator was recalibrated afterwards (1.4 -> 2.0 m/s)
        assert plain['macro']['epsilon'] == 2.0
        plain['macro']['epsilon'] = 1.4
    digest = hashlib.sha256(json.dumps(plain, sort_keys=True).encode()).hexdigest()[:16]
    assert digest == STRAIGHT_CELLS[name]
