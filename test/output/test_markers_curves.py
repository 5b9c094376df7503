"""Markers (and so the Foxglove scene, which is built from them) of a curved belt and a
transfer unit: the sector as triangles within the chord error, the lift as the box height."""

import numpy as np
import pytest

from conveyor_twin.cell import load_cell_text
from conveyor_twin.output import markers as m

from ..viz.curve_cell import CURVE_CELL

pytest.importorskip('visualization_msgs.msg')


def _decode(data: bytes):
    from rclpy.serialization import deserialize_message
    from visualization_msgs.msg import MarkerArray
    return deserialize_message(data, MarkerArray).markers


@pytest.fixture(scope='module')
def cell():
    return load_cell_text(CURVE_CELL)


def _build(cell, lift: float) -> list:
    cm = m.CellMarkers(cell)
    return _decode(cm.build(5_000_000, np.zeros(2, np.uint16), np.array([0.1, 1.5]),
                            np.array([0.0, 0.4]), np.zeros(len(cell.light_barriers), bool),
                            np.array([lift])))


def test_a_curved_belt_is_its_annular_sector_as_triangles(cell):
    bend = cell.belts[1]
    c = bend.curve
    belts = [mk for mk in _build(cell, 0.0) if mk.ns == 'belts']
    straight, curved = sorted(belts, key=lambda mk: mk.id)
    assert straight.type == m.CUBE and curved.type == m.TRIANGLE_LIST
    assert straight.scale.x == pytest.approx(cell.belts[0].length)
    pts = np.array([(p.x, p.y, p.z) for p in curved.points])
    assert len(pts) % 3 == 0 and len(pts) > 0
    assert np.all(pts[:, 2] == -0.005)
    r = np.hypot(pts[:, 0] - c.centre[0], pts[:, 1] - c.centre[1])
    assert np.all(np.isclose(r, c.inner_radius) | np.isclose(r, c.outer_radius))
    # the extent of the belt's surface, short of its outer arc by the chord error at most
    x0, y0, x1, y1 = bend.bounding_box()
    tol = m.CHORD_ERROR + 1e-12
    assert pts[:, 0].min() == pytest.approx(x0, abs=tol)
    assert pts[:, 0].max() == pytest.approx(x1, abs=tol)
    assert pts[:, 1].min() == pytest.approx(y0, abs=tol)
    assert pts[:, 1].max() == pytest.approx(y1, abs=tol)
    # the triangles cover the sector (no gap, no overlap) within the chord error
    tri = pts[:, :2].reshape(-1, 3, 2)
    a, b, d = tri[:, 0], tri[:, 1], tri[:, 2]
    areas = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (d[:, 1] - a[:, 1])
                         - (b[:, 1] - a[:, 1]) * (d[:, 0] - a[:, 0]))
    sector = 0.5 * abs(c.sweep) * (c.outer_radius ** 2 - c.inner_radius ** 2)
    assert sector - 2.0 * m.CHORD_ERROR * bend.length <= areas.sum() <= sector + 1e-12
    # every chord of the outer arc within the chord error of the arc
    outer = pts[np.isclose(r, c.outer_radius)][:, :2]
    mid = 0.5 * (outer[:-1] + outer[1:])
    gap = c.outer_radius - np.hypot(mid[:, 0] - c.centre[0], mid[:, 1] - c.centre[1])
    assert gap.max() <= m.CHORD_ERROR


def test_guide_rails_are_walls_along_the_arcs(cell):
    rails = [mk for mk in _build(cell, 0.0) if mk.ns == 'obstacles' and mk.type == m.LINE_STRIP]
    c = cell.belts[1].curve
    radii = []
    for mk in rails:
        pts = np.array([(p.x, p.y) for p in mk.points])
        r = np.hypot(pts[:, 0] - c.centre[0], pts[:, 1] - c.centre[1])
        if len(pts) > 2:
            radii.append((r.min(), r.max()))
    assert len(radii) == 2
    inner, outer = sorted(radii)
    assert inner[1] <= c.inner_radius and outer[0] >= c.outer_radius


@pytest.mark.parametrize('lift, colour', [(0.0, m.TRANSFER_DOWN), (0.004, m.TRANSFER_DOWN),
                                          (0.005, m.TRANSFER_UP), (0.01, m.TRANSFER_UP)])
def test_a_transfer_unit_is_a_box_as_high_as_its_lift_coloured_by_state(cell, lift, colour):
    act = cell.actuators[0]
    mk, = [mk for mk in _build(cell, lift) if mk.ns == 'actuators']
    assert mk.type == m.CUBE
    assert (mk.pose.position.x, mk.pose.position.y) == pytest.approx(act.base)
    assert (mk.scale.x, mk.scale.y) == pytest.approx((act.length, act.width))
    assert mk.scale.z == pytest.approx(max(lift, 1e-4))
    assert mk.pose.position.z == pytest.approx(0.5 * max(lift, 1e-4))
    got = (mk.color.r, mk.color.g, mk.color.b, mk.color.a)
    assert got == pytest.approx(colour, abs=1e-6)
