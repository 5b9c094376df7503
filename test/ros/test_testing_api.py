"""The public test harness (conveyor_twin.testing): bad use, determinism, both layouts."""

import pytest

from conveyor_twin.bench.testing import make_controller
from conveyor_twin.testing import (CommandRejectedError, ConditionNotMet, LockstepTwin,
                                   quiet_cell, TwinClosedError)

pytestmark = pytest.mark.ros
HASHED = ('parts', 'density', 'light_barriers', 'light_barrier_edges', 'belt_states',
          'actuator_states')


def test_stepping_a_closed_twin_says_so():
    twin = LockstepTwin(quiet_cell())
    with twin:
        twin.step(2)
    assert twin.closed
    with pytest.raises(TwinClosedError, match=r'step\(3\): the twin is closed'):
        twin.step(3)
    with pytest.raises(TwinClosedError, match='set_belt'):
        twin.set_belt('main', 0.1)
    twin.close()  # closing again is harmless


def test_a_command_to_an_unknown_belt_names_it_and_the_known_ones(conveyor_twin):
    with pytest.raises(CommandRejectedError,
                       match=r"unknown belt 'conveyor' \(known: main\)") as raised:
        conveyor_twin.set_belt('conveyor', 0.2)
    assert 'conveyor' in raised.value.reason
    conveyor_twin.step(1)
    with pytest.raises(KeyError, match=r"unknown belt 'conveyor' \(known: main\)"):
        conveyor_twin.belt('conveyor')


def test_a_condition_never_met_names_what_was_waited_for_and_the_state(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), chunk=20)
    with pytest.raises(ConditionNotMet) as raised:
        twin.step_until(lambda: twin.barrier('lb_infeed').blocked, max_steps=50,
                        what='a part at lb_infeed')
    message = str(raised.value)
    assert message.startswith('a part at lb_infeed: not met within 50 steps (0.05 s)')
    assert 'step 50 (t = 0.050 s)' in message and 'main 0.5/0.5 m/s' in message
    assert '0 micro parts' in message
    assert twin.step_index == 50
    with pytest.raises(ConditionNotMet, match='without stepping'):
        twin.wait_until(lambda: False, timeout=0.05, what='nothing')


def _run_with_controller(factory, **kwargs) -> tuple:
    twin = factory(seed=5, **kwargs)
    twin.add_node(make_controller(twin.context))
    twin.step_until(lambda: len(twin.command_log()) >= 2, max_steps=6000,
                    what='the controller stops and restarts the belt')
    twin.step(200)
    log = [(r.target, r.value, r.result) for r in twin.command_log()]
    return {t: twin.digest(t) for t in HASHED}, log, twin.step_index


def test_a_controller_in_this_process_gives_the_same_streams_every_run(conveyor_twin_factory):
    first = _run_with_controller(conveyor_twin_factory)
    again = _run_with_controller(conveyor_twin_factory)
    assert first == again
    digests, log, _ = first
    assert [(target, value) for target, value, _ in log][:2] == [('main', 0.0), ('main', 0.5)]
    assert all(result.accepted for _, _, result in log)


@pytest.mark.slow
def test_split_layout_streams_equal_composed(conveyor_twin_factory):
    runs = []
    for layout in ('composed', 'split'):
        twin = conveyor_twin_factory(seed=2, layout=layout, chunk=50)
        twin.spawn('spacer', [1.9], [0.05])
        twin.step(200)
        twin.set_belt('main', 1.0)
        twin.set_actuator('pusher', 0.3)
        twin.step(200)
        assert len(twin.edges()) == sum(b.edge_count for b in twin.barriers().values())
        runs.append({t: twin.digest(t) for t in HASHED})
        assert twin.edges(), 'the digests should cover edges'
        twin.close()
    assert runs[0] == runs[1]


def test_split_layout_needs_a_cell_file():
    with pytest.raises(ValueError, match='pass a cell file'):
        LockstepTwin(quiet_cell(), layout='split')
    with pytest.raises(ValueError, match="layout 'both' is not one of composed, split"):
        LockstepTwin(layout='both')


def test_command_status_echoes_the_sender_and_sequence_of_each_command(conveyor_twin):
    from conveyor_twin_msgs.msg import BeltCommand
    from diagnostic_msgs.msg import DiagnosticStatus
    import rclpy
    from rclpy.serialization import deserialize_message

    from conveyor_twin.ros.qos import COMMAND_QOS

    twin = conveyor_twin
    other = twin.add_node(rclpy.create_node('other_controller', context=twin.context))
    publisher = other.create_publisher(BeltCommand, 'belt_command', COMMAND_QOS)
    twin.wait_until(lambda: publisher.get_subscription_count() > 0, what='discovery')
    publisher.publish(BeltCommand(belt='main', speed=0.3))               # an old controller
    publisher.publish(BeltCommand(belt='main', speed=0.3, sender='other', sequence=41))
    assert twin.set_belt('main', 0.3).accepted                            # the same command
    twin.step(1)
    records = sorted((r.sender, r.sequence, r.value) for r in twin.command_log())
    assert records == [('', 0, 0.3), ('conveyor_twin_test', 1, 0.3), ('other', 41, 0.3)]
    status = deserialize_message(twin.messages('command_status')[-1], DiagnosticStatus)
    values = {kv.key: kv.value for kv in status.values}
    assert set(values) == {'value', 'step', 'sender', 'sequence'}
    assert twin.set_actuator('pusher', 0.1).step == 1
    assert twin.command_log()[-1][4:] == ('conveyor_twin_test', 2)
