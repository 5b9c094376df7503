"""The encoders against the real generated types (rclpy's serialize/deserialize_message)."""

import os

import numpy as np
import pytest

from conveyor_twin.wire import cdr

pytestmark = pytest.mark.ros
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(60 + os.getpid() % 40))
serialization = pytest.importorskip('rclpy.serialization')
msgs = pytest.importorskip('conveyor_twin_msgs.msg')
from rosgraph_msgs.msg import Clock  # noqa: E402


def assert_same_bytes(mine, theirs):
    """Equal except in padding, which rclpy leaves uninitialised and the encoders zero.

    Fast DDS's serialized length can exceed the data (trailing bytes reserved for alignment of
    empty sequences); the data itself must be a prefix-equal copy.
    """
    assert len(theirs) >= len(mine)
    differing = [i for i in range(len(mine)) if mine[i] != theirs[i]]
    assert all(mine[i] == 0 for i in differing), differing


@pytest.mark.parametrize('n', [0, 1, 5, 1000])
@pytest.mark.parametrize('frame_id', ['', 'cell', 'abcde'])
def test_part_states(n, frame_id):
    rng = np.random.default_rng(n)
    ids = np.arange(1, n + 1, dtype=np.uint32)
    types = rng.integers(0, 4, n).astype(np.uint16)
    arrays = [rng.normal(size=n) for _ in range(6)]
    stamp = 3_600_000_001_000 + n
    data = cdr.encode_part_states(stamp, frame_id, 42, ids, types, *arrays)
    msg = serialization.deserialize_message(data, msgs.PartStates)
    assert msg.header.frame_id == frame_id and msg.step == 42
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(stamp, 10**9)
    assert np.array_equal(msg.id, ids) and np.array_equal(msg.part_type, types)
    for name, array in zip(('x', 'y', 'yaw', 'vx', 'vy', 'wz'), arrays):
        assert np.array_equal(getattr(msg, name), array)
    assert_same_bytes(data, serialization.serialize_message(msg))
    back = cdr.decode_part_states(serialization.serialize_message(msg))
    assert back.step == 42 and np.array_equal(back.wz, arrays[5])


def test_density_grid():
    density = np.arange(12, dtype=np.float64).reshape(3, 4) / 7
    data = cdr.encode_density_grid(5, 'cell', 9, 'macro_1', 0.5, -0.25, 0.02, 4, 3, density,
                                   12.5)
    msg = serialization.deserialize_message(data, msgs.DensityGrid)
    assert (msg.zone, msg.nx, msg.ny, msg.total_parts) == ('macro_1', 4, 3, 12.5)
    assert np.array_equal(msg.density, density.astype(np.float32).ravel())
    assert_same_bytes(data, serialization.serialize_message(msg))


@pytest.mark.parametrize('names', [(), ('lb_in',), ('lb_in', 'lb_mid', 'lb_exit_long')])
def test_light_barrier_states(names):
    n = len(names)
    blocked = [i % 2 == 1 for i in range(n)]
    data = cdr.encode_light_barrier_states(11, 'cell', 3, names, blocked, list(range(n)))
    msg = serialization.deserialize_message(data, msgs.LightBarrierStates)
    assert list(msg.name) == list(names) and list(msg.blocked) == blocked
    assert list(msg.edge_count) == list(range(n))
    assert_same_bytes(data, serialization.serialize_message(msg))


def test_belt_actuator_states_and_edge():
    data = cdr.encode_belt_states(11, 'cell', ('a', 'bb'), [1.0, 2.0], [0.5, 1.5])
    msg = serialization.deserialize_message(data, msgs.BeltStates)
    assert list(msg.speed) == [0.5, 1.5] and list(msg.name) == ['a', 'bb']
    assert_same_bytes(data, serialization.serialize_message(msg))
    data = cdr.encode_actuator_states(11, 'cell', ('pusher', 'arm'), [0.1, 0.2], [0.05, 0.1],
                                      [True, False], [123.5, 0.0])
    msg = serialization.deserialize_message(data, msgs.ActuatorStates)
    assert list(msg.position) == [0.05, 0.1]
    assert list(msg.stalled) == [True, False] and list(msg.load) == [123.5, 0.0]
    assert_same_bytes(data, serialization.serialize_message(msg))
    back = cdr.decode_actuator_states(serialization.serialize_message(msg))
    assert back.stalled.tolist() == [True, False] and back.load.tolist() == [123.5, 0.0]
    data = cdr.encode_light_barrier_edge(1_000_000_007, 'cell', 'lb', True, 9)
    msg = serialization.deserialize_message(data, msgs.LightBarrierEdge)
    assert (msg.name, msg.blocked, msg.part_id, msg.header.stamp.nanosec) == ('lb', True, 9, 7)
    assert_same_bytes(data, serialization.serialize_message(msg))


def test_commands_and_clock():
    wire = serialization.serialize_message(msgs.BeltCommand(belt='main', speed=0.75))
    assert cdr.decode_belt_command(wire) == ('main', 0.75)
    assert_same_bytes(cdr.encode_belt_command('main', 0.75), wire)
    wire = serialization.serialize_message(msgs.BeltCommand(belt='main', speed=0.75,
                                                            sender='ctl', sequence=7))
    assert cdr.decode_command_origin(wire) == ('ctl', 7)
    assert_same_bytes(cdr.encode_belt_command('main', 0.75, 'ctl', 7), wire)
    wire = serialization.serialize_message(msgs.ActuatorCommand(actuator='dv', position=1.0,
                                                                sender='c', sequence=1))
    assert cdr.decode_command_origin(wire, 'ActuatorCommand') == ('c', 1)
    assert_same_bytes(cdr.encode_actuator_command('dv', 1.0, 'c', 1), wire)
    wire = serialization.serialize_message(msgs.ActuatorCommand(actuator='dv', position=-1.5))
    assert cdr.decode_actuator_command(wire) == ('dv', -1.5)
    assert_same_bytes(cdr.encode_actuator_command('dv', -1.5), wire)
    msg = serialization.deserialize_message(cdr.encode_clock(7_000_000_003), Clock)
    assert (msg.clock.sec, msg.clock.nanosec) == (7, 3)
