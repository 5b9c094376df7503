"""The split layout's bytes round-trip exactly (:mod:`conveyor_twin.coord.codec`)."""

import numpy as np
import pytest

from conveyor_twin.coord import codec
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coord.zone_barriers import BarrierValue


def test_payload_kinds_and_step_input() -> None:
    inp = StepInput(12, 12_000_000, np.array([0.25, -1e-17]), np.array([np.pi]))
    payload = codec.step_payload(inp)
    assert payload[:1] == codec.STEP
    back = codec.unpack_step_input(payload[1:])
    assert (back.step, back.time_ns) == (12, 12_000_000)
    assert back.belt_speed.tobytes() == inp.belt_speed.tobytes()
    assert back.actuator_position.tobytes() == inp.actuator_position.tobytes()


def test_cdr_framing_round_trips_and_refuses_other_bytes() -> None:
    payload = codec.done(codec.MACRO_ROLE, 77, b'{"a": 1}')
    assert codec.parse_done(codec.from_cdr(codec.to_cdr(payload))) == (
        codec.MACRO_ROLE, 77, b'{"a": 1}')
    with pytest.raises(ValueError, match='not a conveyor_twin coupling message'):
        codec.from_cdr(b'\x00\x01\x00\x00' + bytes([1, 0, 0, 0]) + bytes(8))
    step, body = codec.parse_stamped(codec.stamped(5, b'xyz'))
    assert step == 5 and bytes(body) == b'xyz'


def test_reset_and_spawn_requests() -> None:
    reset = codec.reset_payload(2 ** 40 + 3, 'cells/a.yaml')
    assert reset[:1] == codec.RESET
    assert codec.parse_reset(reset[1:]) == (2 ** 40 + 3, 'cells/a.yaml')
    assert codec.parse_reset(codec.reset_payload(0, '')[1:]) == (0, '')
    x, y, yaw = np.array([1.0, 2.0]), np.array([0.1, -0.1]), np.array([0.0, 0.5])
    spawn = codec.spawn_payload(3, x, y, yaw)
    assert spawn[:1] == codec.SPAWN
    t, bx, by, byaw = codec.parse_spawn(spawn[1:])
    assert t == 3 and np.array_equal(bx, x) and np.array_equal(by, y)
    assert np.array_equal(byaw, yaw)
    assert list(codec.parse_spawn_reply(codec.spawn_reply(np.array([7, 8])))) == [7, 8]
    with pytest.raises(ValueError, match='nothing placed: overlap'):
        codec.parse_spawn_reply(codec.spawn_error('nothing placed: overlap'))


def test_counters_keep_their_values_under_a_prefix() -> None:
    counters = {'entered': 3, 'in_flight': 0.1 + 0.2, 'balance_residual': -1e-17}
    back = codec.decode_counters('macro', codec.encode_counters(counters))
    assert back == {f'macro_{k}': v for k, v in counters.items()}
    assert codec.decode_counters('micro', b'') == {}


def test_barrier_values_and_edges() -> None:
    barriers = [BarrierValue(2, True, 41), BarrierValue(5, False, 0)]
    edges = [(2, True, 0.123456789), (5, False, 1e-3)]
    data = b'head' + codec.encode_barriers(barriers, edges)
    got, got_edges, end = codec.decode_barriers(data, 4)
    assert got == [(2, True, 41), (5, False, 0)] and got_edges == edges and end == len(data)
