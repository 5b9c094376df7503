"""Commands published by Foxglove clients: JSON values must be finite JSON numbers; anything
else is refused, never applied, and the refusal is counted and reported."""

import json
import struct

import pytest

from conveyor_twin import contract
from conveyor_twin.cell import load_cell
from conveyor_twin.viz.foxglove_messages import CommandParseError, decode_command
from conveyor_twin.viz.foxglove_view import FoxgloveView
from conveyor_twin.wire import cdr

REFUSED = [
    ('{"belt": "main", "speed": "1.5"}', "'1.5' (a string)"),
    ('{"belt": "main", "speed": true}', 'True (a boolean)'),
    ('{"belt": "main", "speed": null}', 'None (null)'),
    ('{"belt": "main", "speed": NaN}', 'NaN is not a finite number'),
    ('{"belt": "main", "speed": Infinity}', 'Infinity is not a finite number'),
    ('{"belt": "main", "speed": 1e999}', 'inf is not a finite number'),
    ('{"belt": "main"}', "'speed' is missing"),
    ('{"speed": 1.0}', "'belt' is missing"),
    ('{"belt": 3, "speed": 1.0}', "'belt': expected a non-empty string"),
    ('{"belt": "main", "speed": [1.0]}', '[1.0] (a JSON list)'),
    ('[1.0]', 'expected a JSON object'),
    ('{"belt": "main", "speed": 1.0', 'not JSON'),
]


@pytest.mark.parametrize('text, reason', REFUSED)
def test_json_commands_that_are_not_finite_numbers_are_refused(text, reason):
    with pytest.raises(CommandParseError) as info:
        decode_command('belt', 'json', text.encode())
    assert reason in str(info.value)


def test_valid_commands_decode():
    assert decode_command('belt', 'json', b'{"belt": "main", "speed": 1}') == ('main', 1.0)
    assert decode_command('actuator', 'json',
                          b'{"actuator": "gate", "position": -0.25}') == ('gate', -0.25)
    assert decode_command('belt', 'cdr', cdr.encode_belt_command('main', 0.5)) == ('main', 0.5)
    with pytest.raises(CommandParseError, match='not a finite number'):
        decode_command('belt', 'cdr', cdr.encode_belt_command('main', float('nan')))
    with pytest.raises(CommandParseError, match='not a valid CDR message'):
        decode_command('belt', 'cdr', b'\x00\x01\x00\x00\x07')
    with pytest.raises(CommandParseError, match="'protobuf' is not cdr or json"):
        decode_command('belt', 'protobuf', b'')


def test_the_view_applies_none_of_the_refused_commands_and_reports_each():
    applied, reported = [], []
    streams = {('/' + t.name).replace('//', '/'): t.type_name for t in contract.STREAMS}
    view = FoxgloveView(load_cell(), streams=streams, step_s=1e-3,
                        on_command=lambda kind, name, value: applied.append((name, value)))
    view.on_invalid = reported.append
    view._advertised((1, 7), '/belt_command', 'json')
    for text, reason in REFUSED:
        assert reason in view.client_message((1, 7), text.encode())
    assert applied == [] and len(reported) == len(REFUSED) == view.rejected
    assert 'not applied' in view.last_rejection
    assert view.client_message((1, 7), b'{"belt": "main", "speed": 1.5}') is None
    assert applied == [('main', 1.5)]


@pytest.mark.ros
def test_a_string_speed_from_a_client_is_rejected_in_diagnostics_and_not_applied(ros_context):
    websockets_client = pytest.importorskip('websockets.sync.client')
    pytest.importorskip('foxglove')
    from conveyor_twin.coord.timing import TimeMode
    from conveyor_twin.wire.decoders import decode_belt_states
    from conveyor_twin.ros.compose import ComposedTwin
    from test.viz.foxglove_wire import (Deadline, SUBPROTOCOL, advertised, messages,
                                        subscribe)
    composed = ComposedTwin(load_cell(), seed=1, mode=TimeMode.REALTIME, context=ros_context,
                            markers_rate=0.0, foxglove='127.0.0.1:0')
    view = composed.foxglove
    composed.start()
    try:
        with websockets_client.connect(f'ws://127.0.0.1:{view.port}',
                                       subprotocols=[SUBPROTOCOL]) as ws:
            channels = advertised(ws, '/belt_states')
            subscribe(ws, channels, ['/belt_states'])
            ws.send(json.dumps({'op': 'advertise', 'channels': [
                {'id': 3, 'topic': '/belt_command', 'encoding': 'json',
                 'schemaName': 'conveyor_twin_msgs/msg/BeltCommand'}]}))
            texts: list = []
            sent = 0
            deadline = Deadline(60.0)
            for _, _, payload in messages(ws, deadline, texts):
                commanded = decode_belt_states(payload).commanded[0]
                if commanded == 0.75:
                    break
                if not sent:  # the server knows the client channel by now
                    for body in (b'{"belt": "main", "speed": "1.5"}',
                                 b'{"belt": "main", "speed": true}',
                                 b'{"belt": "main", "speed": 0.75}'):
                        ws.send(b'\x01' + struct.pack('<I', 3) + body)
                    sent = 1
                elif commanded != 0.75:
                    assert commanded not in (1.5, 1.0)  # never applied
            while not any(t.get('op') == 'status' for t in texts):  # the clients are told
                message = ws.recv(timeout=deadline.left())
                if isinstance(message, str):
                    texts.append(json.loads(message))
        statuses = [t['message'] for t in texts if t.get('op') == 'status']
        assert any("'1.5' (a string)" in s for s in statuses), statuses
        assert view.rejected == 2
        assert composed.twin.commands.rejected_total == 2
        assert 'a boolean' in composed.twin.commands.last_rejection
    finally:
        composed.stop()


def test_an_exception_on_client_input_is_reported_to_the_health():
    """The SDK calls the view on its own thread: an exception there is a named failure."""
    from types import SimpleNamespace
    from conveyor_twin.health import Health
    from conveyor_twin.viz.foxglove_view import CLIENT_FAILURE, _Listener

    def broken(kind, name, value):
        raise RuntimeError('command book broke')

    streams = {('/' + t.name).replace('//', '/'): t.type_name for t in contract.STREAMS}
    health = Health(printer=lambda text: None)
    view = FoxgloveView(load_cell(), streams=streams, step_s=1e-3, on_command=broken,
                        health=health)
    listener = _Listener(view)
    client = SimpleNamespace(id=1)
    listener.on_client_advertise(client, SimpleNamespace(id=7, topic='/belt_command',
                                                         encoding='json'))
    listener.on_message_data(client, 7, b'{"belt": "main", "speed": 1.0}')
    failure, = health.failures
    assert failure.name == CLIENT_FAILURE and 'command book broke' in failure.error
