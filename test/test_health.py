"""Background failures reported once with their traceback, without ROS: the health itself, a
queued sink's consumer, the recorder's writer thread and the stepping thread."""

import os
import subprocess
import sys
import threading

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.runner import Runner, STEPPING_THREAD
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import BackgroundFailure, Health, process_alive
from conveyor_twin.output.frame import Frame
from conveyor_twin.output.queued import QueuedSink
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.writer import McapRecorder, WRITER_NAME

WAIT = 60.0  # s: generous budget for a background thread to fail and report


class Printed:
    """A health printer that keeps what it was given."""

    def __init__(self) -> None:
        self.texts = []

    def __call__(self, text: str) -> None:
        self.texts.append(text)


def _health():
    printed = Printed()
    return Health(printer=printed), printed


def _boom():
    raise ValueError('injected failure')


def test_a_failure_is_reported_once_with_its_traceback():
    health, printed = _health()
    seen = []
    health.listeners.append(seen.append)
    assert health.ok and not health.failed and health.status()[0] is False
    thread = health.thread('worker', _boom)
    thread.start()
    thread.join(WAIT)
    assert health.event.wait(WAIT)
    health.report('worker', RuntimeError('again'))  # counted, not printed again
    assert len(printed.texts) == 1
    assert 'worker failed: ValueError' in printed.texts[0]
    assert 'Traceback' in printed.texts[0] and '_boom' in printed.texts[0]
    assert [f.name for f in seen] == ['worker'] and health.failed and not health.ok
    failed, message = health.status()
    assert failed and 'worker' in message and 'injected failure' in message
    assert health.summary() == [{'name': 'worker', 'error': "ValueError('injected failure')"}]
    with pytest.raises(BackgroundFailure, match='worker'):
        health.raise_if_failed()


def test_a_process_report_carries_its_detail_and_a_listener_cannot_hide_it():
    health, printed = _health()
    health.listeners.append(lambda failure: _boom())
    health.report('node process', message='exited with code -9', detail='last lines\n')
    assert 'node process failed: exited with code -9' in printed.texts[0]
    assert 'last lines' in printed.texts[0]
    assert 'listener raised' in printed.texts[1]
    assert health.failures[0].traceback == 'last lines\n'


def test_process_alive_tells_a_running_from_an_ended_process():
    child = subprocess.Popen([sys.executable, '-c', 'import sys; sys.stdin.read()'],
                             stdin=subprocess.PIPE)
    try:
        assert process_alive(child.pid) and process_alive(os.getpid())
    finally:
        child.stdin.close()
    child.wait(WAIT)
    assert not process_alive(child.pid)


def test_a_queued_sink_consumer_failure_is_reported_and_later_frames_dropped():
    health, printed = _health()

    def consume(frame):
        if frame.step == 3:
            raise KeyError('consumer broke')

    sink = QueuedSink(consume, health=health, name='test viewer')
    for step in range(1, 6):
        frame = Frame()
        frame.step = step
        sink.on_frame(frame)
    assert health.event.wait(WAIT)
    sink.on_frame(Frame())
    sink.close()
    assert [f.name for f in health.failures] == ['test viewer']
    assert 'consumer broke' in printed.texts[0] and 'Traceback' in printed.texts[0]
    assert isinstance(sink.error, KeyError) and sink.dropped >= 1 and sink.delivered == 2


def test_a_failing_recorder_write_is_reported_at_once(tmp_path):
    health, printed = _health()
    recorder = McapRecorder(str(tmp_path / 'broken.mcap'), health=health, flush_period=0.01)
    recorder.add_topic('/clock', 'rosgraph_msgs/msg/Clock')

    def disk_full(*_):
        raise OSError(28, 'No space left on device')

    recorder._file.flush = disk_full
    recorder.record('/clock', 1_000_000, b'\x00\x01\x00\x00' + bytes(8))
    assert health.event.wait(WAIT)  # reported before anyone closes the recorder
    assert [f.name for f in health.failures] == [WRITER_NAME]
    assert 'No space left on device' in printed.texts[0] and 'Traceback' in printed.texts[0]
    with pytest.raises(RecordingError, match='No space left'):
        recorder.close()
    assert len(printed.texts) == 1


@pytest.mark.parametrize('mode', [TimeMode.FAST, TimeMode.REALTIME])
def test_a_failing_step_stops_the_stepping_thread_and_is_reported(mode):
    twin = build_twin(load_cell(), seed=1).twin
    printed = Printed()
    twin.health = Health(printer=printed)
    errors = []

    def listener(inp, commands):
        if inp.step == 5:
            raise ZeroDivisionError('step listener broke')

    twin.step_listeners.append(listener)
    runner = Runner(twin, mode, max_steps=1000, on_error=errors.append)
    runner.warm_up = False
    runner.start()
    assert twin.health.event.wait(WAIT)
    assert runner.wait(WAIT) and not runner.running
    assert runner.steps_done == 4 and twin.step_index == 5
    assert [f.name for f in twin.health.failures] == [STEPPING_THREAD]
    assert 'step listener broke' in printed.texts[0] and 'Traceback' in printed.texts[0]
    assert len(errors) == 1 and isinstance(runner.error, ZeroDivisionError)


def test_a_guarded_thread_that_ends_normally_reports_nothing():
    health, printed = _health()
    done = threading.Event()
    thread = health.thread('quiet', done.set)
    thread.start()
    thread.join(WAIT)
    assert done.is_set() and health.ok and not printed.texts
