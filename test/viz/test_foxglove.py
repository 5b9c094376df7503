"""The live Foxglove view, spoken to by a plain WebSocket client (the ``websockets`` package)."""

import json
import socket
import struct
import time

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.wire.decoders import decode_belt_states
from conveyor_twin.wire import cdr
from test.viz.foxglove_wire import Deadline

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


def _advertised(ws, services: dict = None) -> dict:
    channels: dict = {}
    deadline = Deadline()
    while '/parts' not in channels or (services is not None and not services):
        message = json.loads(ws.recv(timeout=deadline.left()))
        if message['op'] == 'advertise':
            channels.update({c['topic']: c for c in message['channels']})
        elif message['op'] == 'advertiseServices' and services is not None:
            services.update({s['name']: s for s in message['services']})
    return channels


def _messages(ws, deadline: Deadline):
    """Yield (subscription id, log time [ns], payload) of the binary message data received."""
    while True:
        message = ws.recv(timeout=deadline.left())
        if isinstance(message, bytes) and message[0] == 1:
            subscription, log_time = struct.unpack_from('<IQ', message, 1)
            yield subscription, log_time, message[13:]


def _subscribe(ws, channels: dict, topics) -> dict:
    """Subscribe to ``topics``; return subscription id -> topic."""
    ids = {i + 1: topic for i, topic in enumerate(topics)}
    ws.send(json.dumps({'op': 'subscribe', 'subscriptions': [
        {'id': i, 'channelId': channels[topic]['id']} for i, topic in ids.items()]}))
    return ids


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


def test_view_is_fed_only_while_a_client_watches(twin):
    from conveyor_twin.ros.foxglove_bridge import attach
    view = attach(twin, '127.0.0.1:0')
    twin.start()
    try:
        assert view not in twin.output.sinks  # no client: the step pays nothing for the view
        with websockets_client.connect(f'ws://127.0.0.1:{view.port}',
                                       subprotocols=[SUBPROTOCOL]) as ws:
            channels = _advertised(ws)
            _subscribe(ws, channels, ['/clock'])
            deadline = Deadline()
            next(_messages(ws, deadline))
            assert view in twin.output.sinks
        while view in twin.output.sinks:  # the server sees the client go
            time.sleep(0.01)
            deadline.left()
        assert view.counters()['subscriptions'] == 0
    finally:
        twin.runner.stop()
        view.stop()


def test_spawn_parts_is_a_foxglove_service(twin):
    from conveyor_twin_msgs.srv import SpawnParts
    from rclpy.serialization import deserialize_message, serialize_message

    from conveyor_twin.ros.foxglove_bridge import attach
    view = attach(twin, '127.0.0.1:0')
    twin.start()
    try:
        with websockets_client.connect(f'ws://127.0.0.1:{view.port}',
                                       subprotocols=[SUBPROTOCOL]) as ws:
            services: dict = {}
            _advertised(ws, services)
            assert {'/step', '/reset', '/spawn_parts'} <= set(services)
            request = SpawnParts.Request(part_type='spacer', x=[0.3], y=[0.0], yaw=[0.0])
            encoding = b'cdr'
            ws.send(b'\x02' + struct.pack('<III', services['/spawn_parts']['id'], 42,
                                          len(encoding)) + encoding
                    + serialize_message(request))
            deadline = Deadline()
            while True:
                message = ws.recv(timeout=deadline.left())
                if isinstance(message, bytes) and message[0] == 3:
                    break
            service_id, call_id, length = struct.unpack_from('<III', message, 1)
            assert (service_id, call_id) == (services['/spawn_parts']['id'], 42)
            response = deserialize_message(message[13 + length:], SpawnParts.Response)
        assert response.success, response.message
        assert len(response.id) == 1
    finally:
        twin.runner.stop()
        view.stop()


def test_slow_client_never_stalls_the_twin(ros_context):
    """A client that subscribes to everything and never reads: the twin runs 20 000 fast steps
    regardless (the queue and the SDK's per-client backlog are bounded)."""
    from conveyor_twin.ros.compose import ComposedTwin
    steps = 20_000
    composed = ComposedTwin(load_cell(), seed=1, mode=TimeMode.FAST, context=ros_context,
                            markers_rate=0.0, max_steps=steps, foxglove='127.0.0.1:0',
                            foxglove_rate=1000.0)
    view = composed.foxglove
    try:
        with websockets_client.connect(f'ws://127.0.0.1:{view.port}',
                                       subprotocols=[SUBPROTOCOL], max_size=None) as ws:
            channels = _advertised(ws)
            _subscribe(ws, channels, sorted(channels))
            deadline = Deadline()
            while view not in composed.output.sinks:
                time.sleep(0.01)
                deadline.left()
            composed.start()  # and read nothing more
            deadline = Deadline(120.0)
            while composed.twin.step_index < steps:
                time.sleep(0.05)
                deadline.left()
        assert composed.twin.step_index == steps
        assert view.counters()['sent'] > 0
    finally:
        composed.stop()


@pytest.mark.parametrize('subprotocol', ['foxglove.sdk.v1', 'foxglove.websocket.v1'])
def test_both_names_of_the_protocol_are_accepted(twin, subprotocol):
    """Foxglove offers foxglove.sdk.v1; Lichtblick and older Foxglove foxglove.websocket.v1."""
    from conveyor_twin.ros.foxglove_bridge import attach
    view = attach(twin, '127.0.0.1:0')
    twin.start()
    try:
        with websockets_client.connect(f'ws://127.0.0.1:{view.port}',
                                       subprotocols=[subprotocol]) as ws:
            assert ws.subprotocol == subprotocol
            channels = _advertised(ws)
            _subscribe(ws, channels, ['/clock'])
            deadline = Deadline()
            stamps = [log_time for _, (_, log_time, _) in zip(range(3),
                                                             _messages(ws, deadline))]
        assert stamps == sorted(stamps) and len(set(stamps)) == 3
        assert view.counters()['refused_clients'] == 0
    finally:
        twin.runner.stop()
        view.stop()


def test_another_subprotocol_is_refused_plainly_and_the_twin_goes_on(twin):
    from websockets.exceptions import InvalidStatus
    from conveyor_twin.ros.foxglove_bridge import attach
    view = attach(twin, '127.0.0.1:0')
    twin.start()
    try:
        with pytest.raises(InvalidStatus) as info:
            with websockets_client.connect(f'ws://127.0.0.1:{view.port}',
                                           subprotocols=['foxglove.websocket.v2'],
                                           open_timeout=TIMEOUT):
                pass
        response = info.value.response
        assert response.status_code == 400
        text = response.body.decode()
        assert 'foxglove.sdk.v1 or foxglove.websocket.v1' in text
        assert 'offered foxglove.websocket.v2' in text
        assert view.counters()['refused_clients'] == 1
        before = twin.twin.step_index
        deadline = Deadline()
        while twin.twin.step_index <= before:
            time.sleep(0.01)
            deadline.left()
    finally:
        twin.runner.stop()
        view.stop()


def test_lockstep_twin_serves_a_view_of_the_test():
    from conveyor_twin.testing import LockstepTwin
    with LockstepTwin(foxglove='127.0.0.1:0') as test_twin:
        view = test_twin.foxglove
        assert view is not None and view.port > 0
        with websockets_client.connect(f'ws://127.0.0.1:{view.port}',
                                       subprotocols=[SUBPROTOCOL]) as ws:
            channels = _advertised(ws)
            _subscribe(ws, channels, ['/clock'])
            deadline = Deadline()
            while view not in test_twin.composed.output.sinks:
                time.sleep(0.01)
                deadline.left()
            test_twin.step(100)
            stamps = []
            for _, log_time, _ in _messages(ws, deadline):
                stamps.append(log_time)
                if log_time >= 81_000_000:
                    break
        assert stamps == [1_000_000 + 20_000_000 * i for i in range(len(stamps))]
    with pytest.raises(ValueError, match='port other than 0'):
        LockstepTwin(layout='split', foxglove='0')


def test_split_coordinator_serves_the_view_from_its_node_parameter():
    from conveyor_twin.testing import LockstepTwin
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    with LockstepTwin(layout='split', foxglove=f'127.0.0.1:{port}') as test_twin:
        deadline = Deadline(60.0)
        while True:  # the coordinator process opens the server after it started
            try:
                ws = websockets_client.connect(f'ws://127.0.0.1:{port}',
                                               subprotocols=[SUBPROTOCOL])
                break
            except OSError:
                time.sleep(0.1)
                deadline.left()
        with ws:
            channels = _advertised(ws)
            ids = _subscribe(ws, channels, ['/parts', '/belt_states'])
            seen = {'/parts': [], '/belt_states': []}
            deadline = Deadline(60.0)
            while len(seen['/parts']) < 3 or len(seen['/belt_states']) < 3:
                test_twin.step(100)  # the scale streams flow once the new subscriptions match
                try:
                    for sub, log_time, payload in _messages(ws, Deadline(0.5)):
                        seen[ids[sub]].append(log_time)
                except (AssertionError, TimeoutError):
                    pass
                deadline.left()
        for stamps in seen.values():
            gaps = {b - a for a, b in zip(stamps, stamps[1:])}
            assert all(gap > 0 and gap % 20_000_000 == 0 for gap in gaps), gaps
