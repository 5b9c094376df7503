"""``conveyor-twin plant PLANT.yaml --foxglove``: one Foxglove view of every cell, each cell's
scene in its own frame, placed in the plant frame by ``/tf``."""

import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from test.viz.foxglove_wire import (Deadline, SUBPROTOCOL, advertised, messages,
                                    protobuf_fields, subscribe)

pytestmark = [pytest.mark.ros, pytest.mark.slow]
websockets_client = pytest.importorskip('websockets.sync.client')
pytest.importorskip('foxglove')
PLANT = Path(__file__).resolve().parents[2] / 'examples/plant/plant.yaml'
ADDRESS = re.compile(r'Foxglove view at ws://127\.0\.0\.1:(\d+)')


def _lines(stream, into: list) -> None:
    for line in stream:
        into.append(line)


def _frames(payload: bytes) -> set:
    """The parent and child frame names of a protobuf ``foxglove.FrameTransforms``."""
    names = set()
    for transform in protobuf_fields(payload).get(1, []):
        fields = protobuf_fields(transform)
        for number in (2, 3):
            names.update(value.decode() for value in fields.get(number, []))
    return names


@pytest.mark.parametrize('layout', ['--composed', '--processes'])
def test_a_client_sees_parts_of_several_cells_in_one_plant_scene(ros_processes, layout):
    from rclpy.serialization import deserialize_message
    from visualization_msgs.msg import MarkerArray
    from conveyor_twin.plant.loader import load_plant
    from conveyor_twin.testing.processes import stop_process
    plant = load_plant(PLANT)
    proc = ros_processes.start([sys.executable, '-m', 'conveyor_twin.cli', 'plant', str(PLANT),
                                layout, '--mode', 'fast', '--duration', '0', '--quiet',
                                '--foxglove', '127.0.0.1:0'],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err: list = []
    reader = threading.Thread(target=_lines, args=(proc.stderr, err), daemon=True)
    reader.start()
    deadline = Deadline(120.0)
    port = None
    while port is None:
        found = [ADDRESS.search(line) for line in list(err)]
        port = next((int(m.group(1)) for m in found if m), None)
        assert proc.poll() is None, ''.join(err)
        if port is None:
            deadline.left()
            threading.Event().wait(0.05)
    scenes = {f'/{c.namespace}/scene': c.namespace for c in plant.cells}
    with websockets_client.connect(f'ws://127.0.0.1:{port}', subprotocols=[SUBPROTOCOL],
                                   max_size=None) as ws:
        channels = advertised(ws, '/tf')
        assert set(scenes) | {'/infeed/parts', '/sorter/density'} <= set(channels)
        ids = subscribe(ws, channels, sorted(scenes) + ['/tf'])
        with_parts, frames = set(), set()
        deadline = Deadline(180.0)
        for sub, _, payload in messages(ws, deadline):
            topic = ids[sub]
            if topic == '/tf':
                frames |= _frames(payload)
                continue
            for marker in deserialize_message(payload, MarkerArray).markers:
                assert marker.header.frame_id == scenes[topic]  # the cell's own frame
                if marker.ns.startswith('parts/') and len(marker.points):
                    with_parts.add(scenes[topic])
            if len(with_parts) >= 2 and frames >= {'plant'} | set(scenes.values()):
                break
    proc.send_signal(signal.SIGINT)  # Ctrl-C to the parent: it stops its cells itself
    try:
        code = proc.wait(timeout=120.0)
    except subprocess.TimeoutExpired:
        code = stop_process(proc)
    reader.join(10.0)
    assert code == 0, ''.join(err)
    assert 'foxglove plant view' not in ''.join(err)  # no failure of the view's threads
