"""The live Foxglove view, spoken to by a plain WebSocket client (the ``websockets`` package)."""

import json
import socket
import struct

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.record.decode import decode_belt_states
from conveyor_twin.wire import cdr

pytestmark = pytest.mark.ros
websockets_client = pytest.importorskip('websockets.sync.client')
pytest.importorskip('foxglove')
SUBPROTOCOL = 'foxglove.sdk.v1'  # what foxglove-sdk 0.30 speaks (the v1 protocol's messages)
TIMEOUT = 30.0


@pytest.fixture
def twin(ros_context):
    from conveyor_twin.ros.compose import ComposedTwin
    composed = ComposedTwin(load_cell(), seed=1, mode=TimeMode.REALTIME, context=ros_context,
                            markers_rate=0.0)
    yield composed
    composed.stop()


def _advertised(ws) -> dict:
    channels: dict = {}
    while '/parts' not in channels:
        message = json.loads(ws.recv(timeout=TIMEOUT))
        if message['op'] == 'advertise':
            channels.update({c['topic']: c for c in message['channels']})
    return channels


def test_client_sees_parts_and_commands_a_belt(twin):
    from conveyor_twin.ros.foxglove_bridge import attach
    view = attach(twin, '127.0.0.1:0')
    twin.start()
    try:
        with websockets_client.connect(f'ws://127.0.0.1:{view.port}',
                                       subprotocols=[SUBPROTOCOL]) as ws:
            channels = _advertised(ws)
            assert channels['/parts']['encoding'] == 'cdr'
            assert channels['/parts']['schemaEncoding'] == 'ros2msg'
            assert channels['/parts']['schemaName'] == 'conveyor_twin_msgs/msg/PartStates'
            assert {'/belt_states', '/clock', '/diagnostics', '/scene'} <= set(channels)
            ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 1, 'channelId': channels['/parts']['id']},
                {'id': 2, 'channelId': channels['/belt_states']['id']}]}))
            ws.send(json.dumps({'op': 'advertise', 'channels': [
                {'id': 7, 'topic': '/belt_command', 'encoding': 'cdr',
                 'schemaName': 'conveyor_twin_msgs/msg/BeltCommand'}]}))
            commanded, parts = None, []
            sent = False
            while commanded != 1.25 or not parts or len(parts[-1].id) == 0:
                message = ws.recv(timeout=TIMEOUT)
                if not isinstance(message, bytes) or message[0] != 1:
                    continue
                subscription, = struct.unpack_from('<I', message, 1)
                payload = message[13:]  # opcode, subscription id, log time
                if subscription == 1:
                    parts.append(cdr.decode_part_states(payload))
                else:
                    commanded = decode_belt_states(payload).commanded[0]
                    if not sent:  # the server knows the client channel by now
                        for speed in (99.0, 1.25):  # out of range: rejected; then applied
                            ws.send(b'\x01' + struct.pack('<I', 7)
                                    + cdr.encode_belt_command('main', speed))
                        sent = True
        stamps = [p.stamp_ns for p in parts]
        assert stamps == sorted(stamps) and parts[-1].frame_id == 'cell'
        assert view.rejected == 1 and '99' in view.last_rejection
        assert twin.twin.commands.rejected_total == 1
    finally:
        twin.runner.stop()
        view.stop()


def test_port_in_use_and_unknown_host_are_refused(twin):
    from conveyor_twin.ros.foxglove_bridge import attach
    from conveyor_twin.viz.foxglove_view import FoxgloveError, parse_address
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        with pytest.raises(FoxgloveError, match=f'127.0.0.1:{port}'):
            attach(twin, f'127.0.0.1:{port}')
    with pytest.raises(FoxgloveError, match='unknown host'):
        attach(twin, 'no-such-host.invalid:8765')
    with pytest.raises(FoxgloveError, match='0..65535'):
        parse_address('localhost:99999')
    assert parse_address('9000') == ('127.0.0.1', 9000)
    assert twin.twin.step_index == 0  # the twin was never started
