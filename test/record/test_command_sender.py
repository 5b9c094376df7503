"""Accepted commands keep the ``sender`` and ``sequence`` they arrived with: echoed on
``command_status``, recorded, and fed back by re-simulation."""

import pytest

from conveyor_twin.cell import default_cell_text, load_cell
from conveyor_twin.coord.twin import Twin
from conveyor_twin.record import reader
from conveyor_twin.record import resimulate as resim
from conveyor_twin.record.writer import (ACCEPTED_ACTUATOR_COMMANDS, ACCEPTED_BELT_COMMANDS,
                                         McapRecorder)
from conveyor_twin.wire import cdr

pytestmark = pytest.mark.ros

DT_NS = 1_000_000


def recorded_commands(path):
    """Return (step, name, value, sender, sequence) of every recorded accepted command."""
    out = []
    for m in reader.read_messages(str(path), topics=[ACCEPTED_BELT_COMMANDS,
                                                     ACCEPTED_ACTUATOR_COMMANDS]):
        if m.topic == ACCEPTED_BELT_COMMANDS:
            name, value = cdr.decode_belt_command(m.data)
            origin = cdr.decode_command_origin(m.data, 'BeltCommand')
        else:
            name, value = cdr.decode_actuator_command(m.data)
            origin = cdr.decode_command_origin(m.data, 'ActuatorCommand')
        out.append((m.log_time // DT_NS, name, value, *origin))
    return sorted(out)


def scheduled_commands(path):
    """Return (step, name, value, sender, sequence) of the commands re-simulation applies."""
    twin = Twin(load_cell(), seed=0)
    resim._schedule(str(path), twin, DT_NS, resim.ResimReport(str(path)))
    out = []
    for step in range(1, 1000):
        out.extend((c.step, c.name, c.value, c.sender, c.sequence)
                   for c in twin.commands.drain(step))
    return sorted(out)


def test_commands_keep_sender_and_sequence_answered_recorded_and_resimulated(
        tmp_path, conveyor_twin):
    from conveyor_twin_msgs.msg import ActuatorCommand, BeltCommand
    import rclpy

    from conveyor_twin.ros.qos import COMMAND_QOS
    from conveyor_twin.ros.run_recording import TwinRecording

    twin = conveyor_twin
    composed = twin.composed
    path = tmp_path / 'senders.mcap'
    recorder = McapRecorder(str(path), cell_yaml=default_cell_text(), seed=twin.seed,
                            step_ns=composed.twin.dt_ns,
                            metadata={'recorded_by': 'test', 'markers_rate': '0.0',
                                      'namespace': composed.coordinator.get_namespace()},
                            health=composed.twin.health)
    recording = TwinRecording(composed, recorder)
    try:
        ctrl = twin.add_node(rclpy.create_node('ctrl', context=twin.context))
        belt = ctrl.create_publisher(BeltCommand, 'belt_command', COMMAND_QOS)
        actuator = ctrl.create_publisher(ActuatorCommand, 'actuator_command', COMMAND_QOS)
        twin.wait_until(lambda: belt.get_subscription_count() > 0
                        and actuator.get_subscription_count() > 0, what='discovery')
        twin.step(10)

        def answered(sequence):
            return [r for r in twin.command_log() if (r.sender, r.sequence) == ('ctrl', sequence)]

        belt.publish(BeltCommand(belt='main', speed=0.2, sender='ctrl', sequence=7))
        twin.wait_until(lambda: answered(7), what="the answer to ctrl's command 7")
        assert answered(7)[0].result.accepted and answered(7)[0].result.step == 10
        twin.step(20)                                            # in effect at step 11
        assert twin.set_belt('main', 0.4).step == 30             # the harness's own
        twin.step(20)                                            # in effect at step 31
        actuator.publish(ActuatorCommand(actuator='pusher', position=0.1, sender='ctrl',
                                         sequence=8))
        twin.wait_until(lambda: answered(8), what="the answer to ctrl's command 8")
        twin.step(1)                                             # in effect at step 51
        assert twin.set_actuator('pusher', 0.2).step == 51
        twin.step(100)                                           # in effect at step 52
    finally:
        recording.close()
    harness = [(r.sequence, r.value) for r in twin.command_log()
               if r.sender == 'conveyor_twin_test']
    assert harness == [(1, 0.4), (2, 0.2)]
    expected = [(11, 'main', 0.2, 'ctrl', 7), (31, 'main', 0.4, 'conveyor_twin_test', 1),
                (51, 'pusher', 0.1, 'ctrl', 8), (52, 'pusher', 0.2, 'conveyor_twin_test', 2)]
    assert recorded_commands(path) == expected
    assert scheduled_commands(path) == expected              # what re-simulation feeds in
    report = resim.resimulate(str(path), context=twin.context)
    assert report.ok, str(report.difference)
    assert report.commands == 4 and report.compared['/belt_states'] == 151


def test_commands_from_a_foxglove_client_carry_sender_foxglove_numbered(ros_context):
    pytest.importorskip('foxglove')
    from conveyor_twin.coord.timing import TimeMode
    from conveyor_twin.ros.compose import ComposedTwin

    composed = ComposedTwin(load_cell(), seed=1, mode=TimeMode.LOCKSTEP, context=ros_context,
                            markers_rate=0.0, foxglove='127.0.0.1:0')
    try:
        view = composed.foxglove
        view._advertised((4, 3), '/belt_command', 'json')
        view._advertised((4, 5), '/actuator_command', 'json')
        assert view.client_message((4, 3), b'{"belt": "main", "speed": 0.5}') is None
        assert view.client_message((4, 3), b'{"belt": "main", "speed": 9.0}') is not None
        assert view.client_message((4, 5), b'{"actuator": "pusher", "position": 0.1}') is None
        drained = composed.twin.commands.drain(1)
        assert [(c.name, c.sender, c.sequence) for c in drained] == [
            ('main', 'foxglove', 1), ('pusher', 'foxglove', 3)]
    finally:
        composed.stop()
