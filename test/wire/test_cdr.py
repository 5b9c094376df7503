"""CDR encoders against a slow reference serializer and mcap_ros2's independent decoder."""

import struct

import mcap_ros2.decoder
from mcap.records import Schema
import numpy as np
import pytest

from conveyor_twin.wire import cdr
from conveyor_twin.wire.schemas import SCHEMAS
from .reference_cdr import header, serialize

DT_NS = 1_000_000
_decoders = {}


def mcap_decode(type_name, data):
    """Decode with mcap_ros2 (pure Python, reads the ros2msg schema text)."""
    if type_name not in _decoders:
        schema = Schema(id=1, name=type_name, encoding='ros2msg',
                        data=SCHEMAS[type_name].encode())
        _decoders[type_name] = mcap_ros2.decoder.DecoderFactory().decoder_for('cdr', schema)
    return _decoders[type_name](data)


def random_parts(rng, n):
    return (rng.permutation(np.arange(1, 10 * n + 2, dtype=np.uint32))[:n],
            rng.integers(0, 5, n).astype(np.uint16),
            *[rng.normal(size=n) for _ in range(6)])


@pytest.mark.parametrize('n', [0, 1, 2, 3, 7, 1000])
@pytest.mark.parametrize('frame_id', ['', 'c', 'cell', 'abcde', 'zelle_ü'])
def test_part_states_matches_reference(n, frame_id):
    rng = np.random.default_rng(n)
    step = 123_456 + n
    stamp = step * DT_NS
    arrays = random_parts(rng, n)
    data = cdr.encode_part_states(stamp, frame_id, step, *arrays)
    names = ('id', 'part_type', 'x', 'y', 'yaw', 'vx', 'vy', 'wz')
    value = {'header': header(stamp, frame_id), 'step': step}
    value.update({k: [v.item() for v in a] for k, a in zip(names, arrays)})
    ref, _ = serialize('conveyor_twin_msgs/msg/PartStates', value)
    assert data == ref
    decoded = mcap_decode('conveyor_twin_msgs/msg/PartStates', data)
    assert decoded.header.frame_id == frame_id
    assert decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec == stamp
    assert decoded.step == step
    for name, array in zip(names, arrays):
        assert np.array_equal(np.asarray(getattr(decoded, name)), array), name
    back = cdr.decode_part_states(data)
    assert back.stamp_ns == stamp and back.step == step and back.frame_id == frame_id
    for name, array in zip(names, arrays):
        assert np.array_equal(getattr(back, name), array) and getattr(back, name).dtype == \
            array.dtype


def test_part_states_encoder_reuse_changing_counts_and_immutable_output():
    rng = np.random.default_rng(1)
    enc = cdr.PartStatesEncoder('cell', capacity=2)
    outputs = []
    for step, n in enumerate([5, 5, 0, 3, 40, 1, 40]):
        arrays = random_parts(rng, n)
        outputs.append((step, arrays, enc.encode(step * DT_NS, step, *arrays)))
    for step, arrays, data in outputs:  # earlier bytes untouched by later calls
        fresh = cdr.PartStatesEncoder('cell').encode(step * DT_NS, step, *arrays)
        assert data == fresh


def test_part_states_input_conversion():
    """Lists and other dtypes are converted (ids int64 -> uint32, float32 -> float64)."""
    data = cdr.encode_part_states(0, 'cell', 0, [1, 2], np.array([1, 2], np.int64),
                                  np.float32([0.5, 1.5]), [0, 0], [0, 0], [0, 0], [0, 0],
                                  [0, 0])
    back = cdr.decode_part_states(data)
    assert back.id.tolist() == [1, 2] and back.x.tolist() == [0.5, 1.5]


def test_part_states_rejects_unequal_lengths():
    with pytest.raises(cdr.CdrError, match='differ in length'):
        cdr.encode_part_states(0, 'cell', 0, [1, 2], [0, 0], [0.0], [0, 0], [0, 0], [0, 0],
                               [0, 0], [0, 0])


def test_stamps_are_exact_integers():
    for step in (0, 1, 999, 1000, 1001, 2**31 // 1000 * 1000 - 1, 10**9 + 7):
        stamp = step * DT_NS
        if stamp // 10**9 >= 2**31:
            continue
        assert cdr.decode_clock(cdr.encode_clock(stamp)) == stamp
    assert cdr.stamp_parts(3_000_000_001) == (3, 1)
    with pytest.raises(cdr.CdrError):
        cdr.encode_clock(-1)
    with pytest.raises(cdr.CdrError):
        cdr.encode_clock(2**31 * 10**9)


@pytest.mark.parametrize('shape', [(1, 1), (3, 5), (100, 400)])
def test_density_grid(shape):
    ny, nx = shape
    rng = np.random.default_rng(nx)
    density = rng.random(shape) * 100
    args = (42 * DT_NS, 'cell', 42, 'zone_a', 1.25, -0.5, 0.01, nx, ny)
    data = cdr.encode_density_grid(*args, density, 17.5)
    value = {'header': header(42 * DT_NS, 'cell'), 'step': 42, 'zone': 'zone_a',
             'origin_x': 1.25, 'origin_y': -0.5, 'resolution': 0.01, 'nx': nx, 'ny': ny,
             'density': [float(v) for v in density.astype(np.float32).ravel()],
             'total_parts': 17.5}
    assert data == serialize('conveyor_twin_msgs/msg/DensityGrid', value)[0]
    decoded = mcap_decode('conveyor_twin_msgs/msg/DensityGrid', data)
    assert np.array_equal(np.asarray(decoded.density, np.float32),
                          density.astype(np.float32).ravel())
    back = cdr.decode_density_grid(data)
    assert back.density.shape == shape and back.total_parts == 17.5 and back.zone == 'zone_a'
    with pytest.raises(cdr.CdrError, match='grid'):
        cdr.encode_density_grid(*args, np.zeros(nx * ny + 1), 0.0)


@pytest.mark.parametrize('names', [(), ('lb1',), ('a', 'bb', 'ccc', 'dddd', 'entry_z')])
def test_light_barrier_states(names):
    n = len(names)
    blocked = np.arange(n) % 2 == 0
    counts = np.arange(n, dtype=np.uint32) * 3
    data = cdr.encode_light_barrier_states(5 * DT_NS, 'cell', 5, names, blocked, counts)
    value = {'header': header(5 * DT_NS, 'cell'), 'step': 5, 'name': list(names),
             'blocked': blocked.tolist(), 'edge_count': counts.tolist()}
    assert data == serialize('conveyor_twin_msgs/msg/LightBarrierStates', value)[0]
    decoded = mcap_decode('conveyor_twin_msgs/msg/LightBarrierStates', data)
    assert list(decoded.name) == list(names) and list(decoded.blocked) == blocked.tolist()
    back = cdr.decode_light_barrier_states(data)
    assert back[3] == names and back[4].tolist() == blocked.tolist()
    assert back[5].tolist() == counts.tolist()


@pytest.mark.parametrize('kind', ['belt', 'actuator'])
@pytest.mark.parametrize('names', [(), ('main',), ('in', 'main', 'out')])
def test_belt_and_actuator_states(kind, names):
    n = len(names)
    commanded, actual = np.linspace(0, 1, n), np.linspace(-1, 0, n)
    if kind == 'belt':
        data = cdr.encode_belt_states(7, 'cell', names, commanded, actual)
        type_name, fields = 'conveyor_twin_msgs/msg/BeltStates', ('commanded_speed', 'speed')
    else:
        stalled, load = np.arange(n) % 2 == 0, np.linspace(0.0, 250.0, n)
        data = cdr.encode_actuator_states(7, 'cell', names, commanded, actual, stalled, load)
        type_name = 'conveyor_twin_msgs/msg/ActuatorStates'
        fields = ('commanded_position', 'position')
    value = {'header': header(7, 'cell'), 'name': list(names), fields[0]: commanded.tolist(),
             fields[1]: actual.tolist()}
    if kind == 'actuator':
        value.update(stalled=stalled.tolist(), load=load.tolist())
        back = cdr.decode_actuator_states(data)
        assert back.stalled.tolist() == stalled.tolist() and back.load.tolist() == load.tolist()
        assert back.actual.tolist() == actual.tolist() and back.names == tuple(names)
        with pytest.raises(cdr.CdrError):
            cdr.encode_actuator_states(7, 'cell', names, commanded, actual, stalled,
                                       np.zeros(n + 1))
    assert data == serialize(type_name, value)[0]
    decoded = mcap_decode(type_name, data)
    assert list(getattr(decoded, fields[1])) == actual.tolist()
    with pytest.raises(cdr.CdrError):
        cdr.encode_belt_states(7, 'cell', names, commanded, np.zeros(n + 1))


def test_actuator_states_of_the_earlier_layout():
    """A recorded message without the stall fields decodes with none stalled and zero load."""
    pair = cdr.encode_belt_states(7, 'cell', ('pusher',), [0.5], [0.25])  # the same layout
    back = cdr.decode_actuator_states(pair)
    assert back.actual.tolist() == [0.25] and back.stalled.tolist() == [False]
    assert back.load.tolist() == [0.0]
    unset = cdr.decode_actuator_states(cdr.encode_actuator_states(7, 'cell', ('a',), [0], [0]))
    assert unset.stalled.tolist() == [False] and unset.load.tolist() == [0.0]


@pytest.mark.parametrize('blocked', [True, False])
def test_light_barrier_edge(blocked):
    data = cdr.encode_light_barrier_edge(1_234_567_891, 'cell', 'lb_exit', blocked, 77)
    value = {'header': header(1_234_567_891, 'cell'), 'name': 'lb_exit', 'blocked': blocked,
             'part_id': 77}
    assert data == serialize('conveyor_twin_msgs/msg/LightBarrierEdge', value)[0]
    assert mcap_decode('conveyor_twin_msgs/msg/LightBarrierEdge', data).part_id == 77


@pytest.mark.parametrize('name', ['', 'm', 'main', 'belt_number_five'])
def test_commands_round_trip(name):
    for encode, decode, type_name, field in (
            (cdr.encode_belt_command, cdr.decode_belt_command,
             'conveyor_twin_msgs/msg/BeltCommand', ('belt', 'speed')),
            (cdr.encode_actuator_command, cdr.decode_actuator_command,
             'conveyor_twin_msgs/msg/ActuatorCommand', ('actuator', 'position'))):
        data = encode(name, -0.75)
        assert data == serialize(type_name, {field[0]: name, field[1]: -0.75, 'sender': '',
                                             'sequence': 0})[0]
        assert decode(data) == (name, -0.75)
        decoded = mcap_decode(type_name, data)
        assert getattr(decoded, field[0]) == name
        data = encode(name, 1.5, 'controller_' + name, 4_000_000_000)
        assert data == serialize(type_name, {field[0]: name, field[1]: 1.5,
                                             'sender': 'controller_' + name,
                                             'sequence': 4_000_000_000})[0]
        assert decode(data) == (name, 1.5)
        short = type_name.rsplit('/', 1)[1]
        assert cdr.decode_command_origin(data, short) == ('controller_' + name, 4_000_000_000)
        assert mcap_decode(type_name, data).sequence == 4_000_000_000


def test_commands_recorded_without_sender_and_sequence_decode():
    # the bytes of a command as recordings made before the two fields hold them
    old = b'\x00\x01\x00\x00' + b'\x05\x00\x00\x00main\x00' + b'\x00' * 7 + \
        struct.pack('<d', 0.25)
    assert cdr.decode_belt_command(old) == ('main', 0.25)
    assert cdr.decode_command_origin(old) == ('', 0)
    assert cdr.decode_actuator_command(old) == ('main', 0.25)


def test_decode_command_big_endian():
    data = b'\x00\x00\x00\x00' + b'\x00\x00\x00\x05main\x00' + b'\x00' * 7 + \
        struct.pack('>d', 2.5)
    assert cdr.decode_belt_command(data) == ('main', 2.5)


@pytest.mark.parametrize('cut', [0, 3, 4, 7, 10, 15, 19])
def test_decoders_reject_truncated_data(cut):
    data = cdr.encode_belt_command('main', 1.0)
    with pytest.raises(cdr.CdrError):
        cdr.decode_belt_command(data[:cut])


def test_decoders_reject_malformed_data():
    with pytest.raises(cdr.CdrError, match='encapsulation'):
        cdr.decode_belt_command(b'\x00\x07\x00\x00' + bytes(16))
    with pytest.raises(cdr.CdrError, match='NUL'):
        cdr.decode_belt_command(b'\x00\x01\x00\x00\x04\x00\x00\x00mainxxxx' + bytes(8))
    parts = cdr.encode_part_states(0, 'cell', 0, *random_parts(np.random.default_rng(0), 4))
    with pytest.raises(cdr.CdrError):
        cdr.decode_part_states(parts[:-1])
    huge = bytearray(parts)
    huge[36:40] = (2**31).to_bytes(4, 'little')  # id sequence length
    with pytest.raises(cdr.CdrError):
        cdr.decode_part_states(bytes(huge))
    with pytest.raises(cdr.CdrError, match='NUL character'):
        cdr.encode_belt_command('a\x00b', 1.0)
