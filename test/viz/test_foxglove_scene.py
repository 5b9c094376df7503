"""The Foxglove view's scene of a cell with a macro zone: density grids decoded by a plain
WebSocket client, equal to the ``density`` stream of the same step; and failures of the view's
threads reported to the twin's health."""

import time

import numpy as np
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.viz.foxglove_layout import cell_layout, layout_topics
from conveyor_twin.viz.foxglove_view import served_topics
from conveyor_twin.wire import cdr

from test.viz.foxglove_wire import (Deadline, SUBPROTOCOL, advertised, decode_grid, messages,
                                    protobuf_fields, subscribe)

pytestmark = pytest.mark.ros
websockets_client = pytest.importorskip('websockets.sync.client')
pytest.importorskip('foxglove')
MULTISCALE = 'conveyor_twin/cell/examples/multiscale.yaml'


def _stamp_of_grid(payload: bytes) -> int:
    timestamp = protobuf_fields(protobuf_fields(payload)[1][0])
    return timestamp.get(1, [0])[0] * 1_000_000_000 + timestamp.get(2, [0])[0]


def test_grid_encoding_matches_the_sdk():
    """The test's protobuf reader and the SDK's Grid encoder agree on the fields."""
    from conveyor_twin.viz.foxglove_messages import density_grid
    density = np.arange(6, dtype=np.float32).reshape(2, 3)
    grid = cdr.DensityGridData(3_000_000_007, 'cell', 3, 'bulk', 0.5, -0.25, 0.02, density, 1.0)
    payload = density_grid(grid).encode()
    frame_id, columns, data = decode_grid(payload)
    assert (frame_id, columns) == ('cell', 3)
    assert np.array_equal(np.frombuffer(data, '<f4').reshape(2, 3), density)
    assert _stamp_of_grid(payload) == 3_000_000_007


@pytest.fixture
def multiscale(ros_context):
    from conveyor_twin.ros.compose import ComposedTwin
    composed = ComposedTwin(load_cell(MULTISCALE), seed=1, mode=TimeMode.REALTIME,
                            context=ros_context, markers_rate=0.0, foxglove='127.0.0.1:0')
    yield composed
    composed.stop()


def test_density_frames_of_a_macro_zone_decode_to_the_density_stream(multiscale):
    view = multiscale.foxglove
    multiscale.start()
    with websockets_client.connect(f'ws://127.0.0.1:{view.port}', subprotocols=[SUBPROTOCOL],
                                   max_size=None) as ws:
        channels = advertised(ws, '/scene/density/bulk')
        assert channels['/scene/density/bulk']['schemaName'] == 'foxglove.Grid'
        cell = multiscale.cell
        assert set(channels) == set(served_topics(cell))  # the layout's topics, and no other
        assert layout_topics(cell_layout(cell)) <= set(channels)
        ids = subscribe(ws, channels, ['/density', '/scene/density/bulk', '/scene'])
        density = {}   # stamp -> DensityGridData of the ROS stream's bytes
        grids = []     # (stamp, frame_id, columns, data) of the Foxglove grid frames
        scenes = []    # log times of /scene
        matched = None
        deadline = Deadline(60.0)
        for sub, log_time, payload in messages(ws, deadline):
            topic = ids[sub]
            if topic == '/density':
                grid = cdr.decode_density_grid(payload)
                assert grid.stamp_ns == log_time
                density[grid.stamp_ns] = grid
            elif topic == '/scene/density/bulk':
                assert _stamp_of_grid(payload) == log_time
                grids.append((log_time,) + decode_grid(payload))
            else:
                scenes.append(log_time)
            if matched is None:
                for stamp, frame_id, columns, data in grids:
                    ros = density.get(stamp)
                    if ros is not None and ros.total_parts > 0.0:
                        matched = (ros, frame_id, columns, data)
                        scenes_at_match = len(set(scenes))
            elif len(set(scenes)) >= scenes_at_match + 3:  # three newer states drawn
                break
    ros, frame_id, columns, data = matched
    assert frame_id == ros.frame_id and columns == ros.density.shape[1]
    carried = np.frombuffer(data, '<f4').reshape(ros.density.shape)
    assert np.array_equal(carried, ros.density.astype(np.float32))
    assert carried.sum() > 0.0
    assert scenes == sorted(scenes)  # /scene keeps updating (the loop saw newer states)
    assert multiscale.health.ok, multiscale.health.failures
    assert view.counters()['scenes'] > 0


def test_a_failing_scene_thread_is_reported_to_the_twin_health(multiscale, monkeypatch):
    """An exception in the scene thread (here: the grid encoder) is a named failure in the
    twin's health, not a frozen stream with a traceback on standard error."""
    from conveyor_twin.viz import foxglove_view

    def broken(grid):
        raise RuntimeError('grid encoder broke')

    monkeypatch.setattr(foxglove_view, 'density_grid', broken)
    view = multiscale.foxglove
    multiscale.start()
    with websockets_client.connect(f'ws://127.0.0.1:{view.port}', subprotocols=[SUBPROTOCOL],
                                   max_size=None) as ws:
        channels = advertised(ws, '/scene/density/bulk')
        subscribe(ws, channels, ['/scene/density/bulk'])
        deadline = Deadline(60.0)
        while multiscale.health.ok:
            time.sleep(0.05)
            deadline.left()
    failure, = multiscale.health.failures
    assert failure.name == foxglove_view.SCENE_FAILURE
    assert 'grid encoder broke' in failure.error and 'broken' in failure.traceback
    failed, message = multiscale.health.status()
    assert failed and 'foxglove view (scene thread)' in message
