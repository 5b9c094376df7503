"""The frame relay (realtime publishing off the step): every frame to every sink in order,
none dropped even when the sinks are slow, a failure reported once, all queued frames out at
close."""

import threading

import pytest

from conveyor_twin.health import Health
from conveyor_twin.output.frame import Frame
from conveyor_twin.output.relay import FrameRelay

WAIT = 60.0  # s: generous budget for the worker thread


def _frame(step: int) -> Frame:
    frame = Frame()
    frame.step = step
    frame.time_ns = step * 1_000_000
    frame.clock = b'clock%d' % step
    frame.edges = [(frame.time_ns, b'edge%d' % step)]
    return frame


class Recorder:
    """A sink keeping (thread name, step, clock bytes, edges) of every frame; optionally slow."""

    def __init__(self, gate: threading.Event = None) -> None:
        self.seen = []
        self.gate = gate

    def on_frame(self, frame: Frame) -> None:
        if self.gate is not None:
            assert self.gate.wait(WAIT)
        self.seen.append((threading.current_thread().name, frame.step, frame.clock,
                          tuple(frame.edges)))


def test_every_frame_reaches_every_sink_in_order_on_the_relay_thread():
    first, second, after = Recorder(), Recorder(), []
    relay = FrameRelay([first, second], name='relay under test',
                       after=lambda f: after.append(f.step))
    frame = Frame()  # one object reused, as the twin does
    for step in range(1, 501):
        fresh = _frame(step)
        for name in Frame.__slots__:
            setattr(frame, name, getattr(fresh, name))
        relay.on_frame(frame)
    relay.close(WAIT)
    for sink in (first, second):
        assert [s[1] for s in sink.seen] == list(range(1, 501))
        assert all(clock == b'clock%d' % step for _, step, clock, _ in sink.seen)
        assert all(edges == ((step * 1_000_000, b'edge%d' % step),)
                   for _, step, _, edges in sink.seen)
        assert {s[0] for s in sink.seen} == {'relay under test'}
    assert after == list(range(1, 501))
    assert relay.delivered == 500 and relay.dropped == 0 and relay.pending == 0


def test_a_full_queue_makes_the_step_wait_and_loses_nothing():
    gate = threading.Event()
    sink = Recorder(gate)
    relay = FrameRelay([sink], capacity=4)
    stepping = threading.Thread(target=lambda: [relay.on_frame(_frame(s)) for s in range(1, 21)])
    stepping.start()
    stepping.join(0.5)
    assert stepping.is_alive()  # waiting for room: the sink holds the first frame
    assert relay.waits >= 1 and relay.pending <= 4
    gate.set()
    stepping.join(WAIT)
    assert not stepping.is_alive()
    assert relay.flush(WAIT)
    assert [s[1] for s in sink.seen] == list(range(1, 21))
    relay.close(WAIT)


def test_a_failing_sink_is_reported_once_and_later_frames_are_counted_not_queued():
    health = Health()

    class Failing:
        def on_frame(self, frame: Frame) -> None:
            if frame.step == 3:
                raise ArithmeticError('publish injected')

    relay = FrameRelay([Failing()], name='publisher thread', health=health)
    for step in range(1, 4):
        relay.on_frame(_frame(step))
    assert not relay.flush(WAIT)  # False: the worker failed
    assert relay.delivered == 2
    (failure,) = health.failures
    assert failure.name == 'publisher thread' and 'publish injected' in failure.error
    assert 'Traceback' in failure.traceback
    relay.on_frame(_frame(4))
    relay.on_frame(_frame(5))
    assert relay.dropped == 3 and len(health.failures) == 1  # the failed one, 4 and 5
    relay.close(WAIT)


def test_close_relays_what_is_queued_and_a_closed_relay_counts_later_frames():
    gate = threading.Event()
    sink = Recorder(gate)
    relay = FrameRelay([sink])
    for step in range(1, 11):
        relay.on_frame(_frame(step))
    gate.set()
    relay.close(WAIT)
    assert [s[1] for s in sink.seen] == list(range(1, 11))
    relay.on_frame(_frame(11))
    assert relay.dropped == 1 and len(sink.seen) == 10


def test_capacity_must_be_positive():
    with pytest.raises(ValueError, match='capacity 0'):
        FrameRelay([], capacity=0)
