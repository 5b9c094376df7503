"""The DiagnosticArray encoder against rclpy's serializer and mcap_ros2's independent decoder."""

import mcap_ros2.decoder
from mcap.records import Schema
import numpy as np
import pytest

from conveyor_twin.wire.builder import CdrError
from conveyor_twin.wire.decoders import decode_diagnostic_array
from conveyor_twin.wire.diagnostics import encode_diagnostic_array, ERROR, OK, Status, WARN
from conveyor_twin.wire.schemas import SCHEMAS

TYPE = 'diagnostic_msgs/msg/DiagnosticArray'


def random_statuses(rng):
    """0-4 statuses of random levels and strings (empty, ASCII, UTF-8), 0-6 pairs each."""
    def text():
        return ''.join(rng.choice(list('ab_:. 0123é€')) for _ in range(rng.integers(0, 12)))

    return [Status(int(rng.integers(0, 4)), text(), text(), text(),
                   tuple((text(), text()) for _ in range(rng.integers(0, 7))))
            for _ in range(rng.integers(0, 5))]


def mcap_decode(data):
    schema = Schema(id=1, name=TYPE, encoding='ros2msg', data=SCHEMAS[TYPE].encode())
    return mcap_ros2.decoder.DecoderFactory().decoder_for('cdr', schema)(data)


@pytest.mark.parametrize('seed', range(40))
def test_round_trip_and_independent_decoder(seed):
    rng = np.random.default_rng(seed)
    statuses = random_statuses(rng)
    stamp = int(rng.integers(0, 2**31)) * 10**9 + int(rng.integers(0, 10**9))
    frame_id = ['', 'c', 'cell', 'zelle_ü'][seed % 4]
    data = encode_diagnostic_array(stamp, frame_id, statuses)
    assert decode_diagnostic_array(data) == (stamp, frame_id, tuple(statuses))
    msg = mcap_decode(data)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(stamp, 10**9)
    assert msg.header.frame_id == frame_id
    assert [(s.level, s.name, s.message, s.hardware_id,
             tuple((kv.key, kv.value) for kv in s.values)) for s in msg.status] == statuses
    assert encode_diagnostic_array(stamp, frame_id, statuses) == data  # padding is zero


def test_rclpy_message_objects_give_the_same_bytes_as_rclpy():
    serialization = pytest.importorskip('rclpy.serialization')
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    rng = np.random.default_rng(7)
    for _ in range(30):
        statuses = random_statuses(rng)
        msg = DiagnosticArray(status=[DiagnosticStatus(
            level=bytes([s.level]), name=s.name, message=s.message, hardware_id=s.hardware_id,
            values=[KeyValue(key=k, value=v) for k, v in s.values]) for s in statuses])
        msg.header.stamp = Time(sec=12, nanosec=345)
        msg.header.frame_id = 'cell'
        theirs = serialization.serialize_message(msg)
        mine = encode_diagnostic_array(12_000_000_345, 'cell', statuses)
        # the message objects encode like the tuples
        assert encode_diagnostic_array(12_000_000_345, 'cell', msg.status) == mine
        # rclpy leaves padding uninitialised; everything else is equal
        assert len(mine) == len(theirs)
        assert all(a == b or a == 0 for a, b in zip(mine, theirs))
        assert serialization.deserialize_message(mine, DiagnosticArray) == msg


def test_bad_input_is_named():
    with pytest.raises(CdrError, match='NUL'):
        encode_diagnostic_array(0, 'cell', [Status(OK, 'a\x00b', '', '', ())])
    with pytest.raises(CdrError, match='level 256'):
        encode_diagnostic_array(0, 'cell', [Status(256, 'a', '', '', ())])
    with pytest.raises(CdrError, match='stamp'):
        encode_diagnostic_array(-1, 'cell', [])
    assert WARN == 1 and ERROR == 2
