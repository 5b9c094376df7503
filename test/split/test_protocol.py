"""The split layout's bytes round-trip exactly (:mod:`conveyor_twin.split.protocol`)."""

import numpy as np
import pytest

from conveyor_twin.coord.layout import Role
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coupling.zone_barriers import BarrierValue
from conveyor_twin.split import protocol


def test_payload_kinds_and_step_input() -> None:
    inp = StepInput(12, 12_000_000, np.array([0.25, -1e-17]), np.array([np.pi]))
    payload = protocol.step_payload(inp)
    assert payload[:1] == protocol.STEP
    back = protocol.unpack_step_input(payload[1:])
    assert (back.step, back.time_ns) == (12, 12_000_000)
    assert back.belt_speed.tobytes() == inp.belt_speed.tobytes()
    assert back.actuator_position.tobytes() == inp.actuator_position.tobytes()


def test_cdr_framing_round_trips_and_refuses_other_bytes() -> None:
    payload = protocol.done(Role.MACRO, 77, b'{"a": 1}')
    assert protocol.parse_done(protocol.from_cdr(protocol.to_cdr(payload))) == (
        Role.MACRO, 77, b'{"a": 1}')
    with pytest.raises(ValueError, match='not a conveyor_twin coupling message'):
        protocol.from_cdr(b'\x00\x01\x00\x00' + bytes([1, 0, 0, 0]) + bytes(8))
    step, body = protocol.parse_stamped(protocol.stamped(5, b'xyz'))
    assert step == 5 and bytes(body) == b'xyz'


def test_reset_and_spawn_requests() -> None:
    reset = protocol.reset_payload(2 ** 40 + 3, 'cells/a.yaml')
    assert reset[:1] == protocol.RESET
    assert protocol.parse_reset(reset[1:]) == (2 ** 40 + 3, 'cells/a.yaml')
    assert protocol.parse_reset(protocol.reset_payload(0, '')[1:]) == (0, '')
    x, y, yaw = np.array([1.0, 2.0]), np.array([0.1, -0.1]), np.array([0.0, 0.5])
    spawn = protocol.spawn_payload(3, x, y, yaw)
    assert spawn[:1] == protocol.SPAWN
    t, bx, by, byaw = protocol.parse_spawn(spawn[1:])
    assert t == 3 and np.array_equal(bx, x) and np.array_equal(by, y)
    assert np.array_equal(byaw, yaw)
    assert list(protocol.parse_spawn_reply(protocol.spawn_reply(np.array([7, 8])))) == [7, 8]
    with pytest.raises(ValueError, match='nothing placed: overlap'):
        protocol.parse_spawn_reply(protocol.spawn_error('nothing placed: overlap'))


def test_counters_keep_their_values_under_a_prefix() -> None:
    counters = {'entered': 3, 'in_flight': 0.1 + 0.2, 'balance_residual': -1e-17}
    back = protocol.decode_counters('macro', protocol.encode_counters(counters))
    assert back == {f'macro_{k}': v for k, v in counters.items()}
    assert protocol.decode_counters('micro', b'') == {}


def test_barrier_values_and_edges() -> None:
    barriers = [BarrierValue(2, True, 41), BarrierValue(5, False, 0)]
    edges = [(2, True, 0.123456789), (5, False, 1e-3)]
    data = b'head' + protocol.encode_barriers(barriers, edges)
    got, got_edges, end = protocol.decode_barriers(data, 4)
    assert got == [(2, True, 41), (5, False, 0)] and got_edges == edges and end == len(data)
