"""StepHandshake: a PLC steps a lockstep twin, exactly as far as it asked."""

import threading

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.plc.lockstep import StepHandshake
from conveyor_twin.plc.writes import WriteRejected


def handshake_on_a_twin(lockstep: bool = True, max_steps: int = 100_000):
    built = build_twin(load_cell(), seed=1)
    return built, StepHandshake(built.step, mode_is_lockstep=lockstep, max_steps=max_steps,
                                index=lambda: built.twin.step_index)


def test_request_steps_exactly_n_and_returns_the_step_index() -> None:
    built, handshake = handshake_on_a_twin()
    assert handshake.request(7) == 7
    assert handshake.request(1) == 8
    assert built.twin.step_index == 8 and handshake.steps == 8
    assert handshake.done


def test_without_an_index_it_returns_its_own_steps() -> None:
    calls = []
    handshake = StepHandshake(calls.append, mode_is_lockstep=True)
    assert handshake.request(3) == 3 and handshake.request(2) == 5
    assert calls == [3, 2]


def test_outside_lockstep_every_request_is_refused() -> None:
    built, handshake = handshake_on_a_twin(lockstep=False)
    with pytest.raises(WriteRejected, match='not in lockstep mode') as info:
        handshake.request(1)
    assert info.value.reason == 'not_lockstep'
    with pytest.raises(WriteRejected, match='not in lockstep'):
        handshake.on_tick(1)
    assert built.twin.step_index == 0 and handshake.tick == 0


@pytest.mark.parametrize('n, reason, message', [
    (0, 'out_of_range', r'0 steps is outside \[1, 50\]'),
    (-3, 'out_of_range', r'-3 steps is outside \[1, 50\]'),
    (51, 'out_of_range', r'51 steps is outside \[1, 50\]'),
    (2.0, 'bad_type', '2.0 is not an integer'),
    (True, 'bad_type', 'True is not an integer'),
])
def test_n_out_of_range_is_refused(n, reason, message) -> None:
    built, handshake = handshake_on_a_twin(max_steps=50)
    with pytest.raises(WriteRejected, match=message) as info:
        handshake.request(n)
    assert info.value.reason == reason
    assert built.twin.step_index == 0
    assert handshake.request(50) == 50


def test_tick_protocol_steps_tick_steps_per_increment_and_wraps() -> None:
    built, handshake = handshake_on_a_twin()
    assert handshake.on_tick(1) and built.twin.step_index == 10
    assert not handshake.on_tick(1) and built.twin.step_index == 10  # the same tick again
    handshake.set_tick_steps(3)
    assert handshake.on_tick(2) and built.twin.step_index == 13
    assert (handshake.tick, handshake.done_tick) == (2, 2)
    with pytest.raises(WriteRejected, match='expected 3'):
        handshake.on_tick(5)
    with pytest.raises(WriteRejected, match=r'\[0, 65535\]'):
        handshake.on_tick(70000)
    with pytest.raises(WriteRejected, match=r'outside \[1, 100000\]'):
        handshake.set_tick_steps(0)
    handshake.tick = handshake.done_tick = 65535
    assert handshake.on_tick(0) and handshake.done_tick == 0
    assert built.twin.step_index == 16


def test_two_threads_requesting_at_once_step_the_sum() -> None:
    built, handshake = handshake_on_a_twin()
    errors = []

    def ask() -> None:
        try:
            for _ in range(50):
                handshake.request(2)
        except BaseException as exc:  # noqa: B902 - handed to the test
            errors.append(exc)
    threads = [threading.Thread(target=ask) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=120)
    assert not errors and not any(t.is_alive() for t in threads)
    assert built.twin.step_index == 200 and handshake.steps == 200 and handshake.done


def test_bad_max_steps_is_refused() -> None:
    with pytest.raises(ValueError, match='max_steps 0'):
        StepHandshake(lambda n: None, mode_is_lockstep=True, max_steps=0)
