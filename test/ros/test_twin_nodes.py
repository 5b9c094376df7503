"""Launch-free integration tests of the composed twin: streams, lockstep, commands, services.

They drive the twin through the public test harness (:mod:`conveyor_twin.testing`); the checks
that nothing invalid was applied also look inside the in-process twin.
"""

import math
import re

from conveyor_twin_msgs.msg import BeltStates
import numpy as np
import pytest
from rclpy.serialization import deserialize_message

from conveyor_twin.testing import CommandRejectedError, LockstepTwin, quiet_cell, ServiceError
from conveyor_twin.wire import cdr

pytestmark = pytest.mark.ros


@pytest.fixture
def twin(conveyor_twin_factory) -> LockstepTwin:
    return conveyor_twin_factory(quiet_cell(), seed=7, chunk=50)


@pytest.mark.smoke
def test_lockstep_step_advances_exactly_n_and_every_stream_has_consecutive_steps(twin):
    assert twin.step(25) == 25
    assert twin.time_ns == 25_000_000
    assert twin.step(1) == 26
    parts = [cdr.decode_part_states(d).step for d in twin.messages('parts')]
    assert parts == list(range(1, 27))
    barriers = [cdr.decode_light_barrier_states(d)[2] for d in twin.messages('light_barriers')]
    assert barriers == list(range(1, 27))
    # belt and actuator states carry no step field: their stamps advance by exactly one step
    for topic in ('belt_states', 'actuator_states'):
        stamps = [int.from_bytes(d[4:8], 'little') * 10**9 + int.from_bytes(d[8:12], 'little')
                  for d in twin.messages(topic)]
        assert stamps == [k * 1_000_000 for k in range(1, 27)]
    assert twin.composed.twin.step_index == 26


def test_belt_command_changes_belt_states_and_part_motion(twin):
    ids = twin.spawn('spacer', [1.0], [0.0])
    twin.step(400)  # the part takes up the belt speed 0.5 m/s
    moving = twin.parts()
    assert list(moving.id) == list(ids)
    assert moving.vx[0] == pytest.approx(0.5, abs=0.01)
    assert twin.set_belt('main', 0.0).accepted
    twin.step(600)
    state = deserialize_message(twin.messages('belt_states')[-1], BeltStates)
    assert list(state.name) == ['main']
    assert state.commanded_speed[0] == 0.0 and state.speed[0] == 0.0
    assert twin.belt('main') == (0.0, 0.0)
    stopped = twin.parts()
    assert abs(stopped.vx[0]) < 1e-3  # carried to rest by belt friction
    assert stopped.x[0] > moving.x[0]


def test_pusher_command_moves_parts(twin):
    pusher = twin.cell.actuators[twin.cell.actuator_index('pusher')]
    (part,) = twin.spawn('spacer', [pusher.base[0]], [0.1])
    twin.set_belt('main', 0.0)
    twin.step(300)  # belt and part at rest in front of the pusher
    before = twin.parts()
    twin.set_actuator('pusher', 0.5)
    twin.step(800)
    after = twin.part(part)
    assert after is None or after['y'] < 0.0, (before.y, after)
    assert twin.actuator('pusher').commanded_position == 0.5


@pytest.mark.parametrize('topic, target, value, reason', [
    ('belt_command', 'nope', 0.1, "unknown belt 'nope' (known: main)"),
    ('belt_command', 'main', math.nan, 'is not finite'),
    ('belt_command', 'main', 3.0, 'outside'),
    ('actuator_command', 'pusher', -0.2, 'outside'),
    ('actuator_command', 'gripper', 0.1, "unknown actuator 'gripper'"),
    ('actuator_command', 'stopper', math.inf, 'is not finite'),
])
def test_invalid_commands_are_rejected_counted_and_not_applied(twin, topic, target, value,
                                                               reason):
    twin.step(5)
    core = twin.composed.twin
    targets = (core.actuation.belt_target.copy(), core.actuation.actuator_target.copy())
    send = twin.set_belt if topic == 'belt_command' else twin.set_actuator
    result = send(target, value, check=False)
    assert not result.accepted and reason in result.reason and result.step == 5
    assert core.commands.rejected_total == 1
    with pytest.raises(CommandRejectedError, match=re.escape(reason)):
        send(target, value)
    twin.step(5)
    assert np.array_equal(core.actuation.belt_target, targets[0])
    assert np.array_equal(core.actuation.actuator_target, targets[1])
    assert twin.composed.coordinator.summary()['rejected_commands'] == 2
    diag = twin.composed.coordinator.diagnostics(core.time_ns)
    values = {kv.key: kv.value for kv in diag.status[0].values}
    assert values['rejected_commands'] == '2' and values['last_rejection']
    log = twin.command_log()
    assert [(r.topic, r.target, r.result.accepted) for r in log] == [(topic, target, False)] * 2


def test_valid_commands_are_answered_accepted_and_take_effect_at_the_next_step(twin):
    twin.step(3)
    result = twin.set_belt('main', 0.2)
    assert result == (True, '', 3)
    assert twin.belt('main').commanded_speed == 0.5  # not yet applied
    twin.step(1)
    assert twin.belt('main').commanded_speed == 0.2


def test_spawn_refuses_parts_outside_the_cell(twin):
    with pytest.raises(ServiceError) as refused:
        twin.spawn('spacer', [1.0, 1e6], [0.0, 1e6])
    message = str(refused.value)
    assert 'part 1 (spacer) at x = 1e+06 m, y = 1e+06 m is not on a belt' in message, message
    assert "allowed: a centre on belt 'main'" in message and 'nothing placed' in message
    twin.step(1)
    assert len(twin.parts().id) == 0
    assert len(twin.spawn('spacer', [1.0], [0.0])) == 1


def test_spawn_rejects_bad_requests(twin):
    with pytest.raises(ServiceError, match="'bolt'"):
        twin.spawn('bolt', [1.0], [0.0])
    with pytest.raises(ServiceError, match='same'):
        twin.spawn('spacer', [1.0, 1.1], [0.0], [0.0])
    with pytest.raises(ServiceError):
        twin.spawn('spacer', [1.0, 1.001], [0.0, 0.0])
    twin.step(1)
    assert len(twin.parts().id) == 0


def test_reset_restarts_at_step_zero(twin):
    twin.step(10)
    twin.reset(seed=11)
    assert twin.step(3) == 3
    with pytest.raises(ServiceError, match='nonexistent.yaml'):
        twin.reset(seed=1, cell_file='/nonexistent.yaml')
