"""The Foxglove scene of a cell with a curved belt and a transfer unit: the sector at its
extent, the transfer unit up or down as the latest ``actuator_states`` say."""

from pathlib import Path

import numpy as np
import pytest

from conveyor_twin import contract
from conveyor_twin.cell import load_cell
from conveyor_twin.output import markers as m
from conveyor_twin.viz.foxglove_layout import belt_x_max, cell_layout
from conveyor_twin.viz.foxglove_loops import cell_scene
from conveyor_twin.wire import cdr

pytest.importorskip('visualization_msgs.msg')
EXAMPLES = Path(m.__file__).resolve().parents[1] / 'cell' / 'examples'


def _scene(cell, position) -> list:
    from rclpy.serialization import deserialize_message
    from visualization_msgs.msg import MarkerArray
    stamp = 7_000_000
    n = 2
    parts = cdr.encode_part_states(stamp, 'cell', 7, np.arange(1, n + 1, dtype=np.uint32),
                                   np.zeros(n, np.uint16), np.array([0.5, 2.3]),
                                   np.array([0.0, 0.2]), np.zeros(n), np.zeros(n),
                                   np.zeros(n), np.zeros(n))
    names = tuple(a.name for a in cell.actuators)
    acts = cdr.encode_actuator_states(stamp, 'cell', names, position, position)
    latest = {contract.PARTS.name: (stamp, parts), contract.ACTUATOR_STATES.name: (stamp, acts)}
    got, data = cell_scene(m.CellMarkers(cell), cell, latest)
    assert got == stamp
    return deserialize_message(data, MarkerArray).markers


def test_the_scene_of_the_l_line_holds_its_curve():
    cell = load_cell(EXAMPLES / 'l_line.yaml')
    index = next(i for i, b in enumerate(cell.belts) if b.curve is not None)
    bend = cell.belts[index]
    mk, = [mk for mk in _scene(cell, np.zeros(len(cell.actuators)))
           if mk.ns == 'belts' and mk.id == index]
    assert mk.type == m.TRIANGLE_LIST
    pts = np.array([(p.x, p.y) for p in mk.points])
    x0, y0, x1, y1 = bend.bounding_box()
    tol = m.CHORD_ERROR + 1e-12
    assert (pts[:, 0].min(), pts[:, 1].min(), pts[:, 0].max(), pts[:, 1].max()) == \
        pytest.approx((x0, y0, x1, y1), abs=tol)
    # the layout's camera looks at the middle of everything, the curve included
    target = cell_layout(cell)['configById']['3D!scene']['cameraState']['targetOffset'][0]
    assert target == pytest.approx(0.5 * max(belt_x_max(b) for b in cell.belts))
    assert max(belt_x_max(b) for b in cell.belts) >= x1 - tol


def test_the_scene_shows_the_transfer_unit_up_and_down():
    cell = load_cell(EXAMPLES / 'transfer.yaml')
    index = next(i for i, a in enumerate(cell.actuators) if a.kind == 'transfer')
    act = cell.actuators[index]
    for lift, colour in ((0.0, m.TRANSFER_DOWN), (act.position_range[1], m.TRANSFER_UP)):
        position = np.array([a.initial_position for a in cell.actuators])
        position[index] = lift
        mk, = [mk for mk in _scene(cell, position) if mk.ns == 'actuators' and mk.id == index]
        assert mk.scale.z == pytest.approx(max(lift, 1e-4))
        assert (mk.color.r, mk.color.g, mk.color.b) == pytest.approx(colour[:3], abs=1e-6)
