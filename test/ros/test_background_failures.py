"""A failure of any thread or process of a run is reported once with its traceback, sets the
diagnostics' ``conveyor_twin: health`` status to ERROR naming it, and ends the run non-zero.

Each test injects one failure: the markers thread, the stepping thread and the recorder's
writer of ``conveyor-twin run`` (in this process), a queued sink's consumer and an executor
callback of a composed twin, a scale node process's executor thread, and a scale node process
killed with SIGKILL during ``conveyor-twin run --split``.
"""

import contextlib
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading

from conveyor_twin_msgs.msg import BeltCommand
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rclpy.serialization import deserialize_message

from conveyor_twin import contract
from conveyor_twin.cell import load_cell
from conveyor_twin.cli import run as cli_run
from conveyor_twin.coord.runner import STEPPING_THREAD
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE
from conveyor_twin.output.queued import QueuedSink
from conveyor_twin.record import reader
from conveyor_twin.record.writer import WRITER_NAME
from conveyor_twin.ros.compose import ComposedTwin, EXECUTOR
from conveyor_twin.ros.coordinator_node import CoordinatorNode, HEALTH_STATUS
from conveyor_twin.ros.endpoints import create_subscription
from conveyor_twin.ros.micro_node import MARKERS_THREAD
from conveyor_twin.split.launch import ros_args
from conveyor_twin.testing.ros_env import wait_for

pytestmark = pytest.mark.ros
WAIT = 120.0  # s: generous budget for a failure to be noticed, a run to stop
START = 600.0  # s: generous budget for three processes to load their kernels and connect
LONG = '600'  # s of simulated time: a run that only a failure ends within a test


def health_status(data: bytes) -> DiagnosticStatus:
    """Return the ``conveyor_twin: health`` status of a DiagnosticArray's CDR."""
    array = deserialize_message(data, DiagnosticArray)
    (status,) = [s for s in array.status if s.name == HEALTH_STATUS]
    return status


def assert_error_names(data: bytes, name: str) -> None:
    status = health_status(data)
    assert status.level == DiagnosticStatus.ERROR, status
    assert name in status.message and name in {v.key for v in status.values}, status


@pytest.fixture
def final_diagnostics(monkeypatch):
    """The diagnostics each coordinator published after a failure (CDR), in order."""
    published = []
    original = CoordinatorNode.publish_diagnostics

    def spy(self, *args, **kwargs):
        data = original(self, *args, **kwargs)
        published.append(data)
        return data

    monkeypatch.setattr(CoordinatorNode, 'publish_diagnostics', spy)
    return published


@pytest.fixture
def in_process_run():
    """Run ``conveyor-twin run`` in this process; its signal handlers are undone after."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

    def run(*args):
        return cli_run.main(['--mode', 'fast', '--quiet', '--json', '--markers-rate', '30',
                             *args])

    yield run
    for sig, handler in saved.items():
        signal.signal(sig, handler)


def _summary(out: str) -> dict:
    return json.loads(out.strip().splitlines()[-1])


def _check_run(code, capfd, name: str, text: str):
    """The run exited with the background-failure code, reported ``name`` once with its
    traceback and named it in the summary; return (summary, stderr)."""
    out, err = capfd.readouterr()
    assert code == EXIT_BACKGROUND_FAILURE, err[-4000:]
    assert err.count(f'conveyor_twin: {name} failed:') == 1, err[-4000:]
    report = err[err.index(f'conveyor_twin: {name} failed:'):]
    assert 'Traceback' in report and text in report, err[-4000:]
    summary = _summary(out)
    assert name in [f['name'] for f in summary['failures']], summary
    return summary, err


def _recorded_diagnostics(path: Path):
    return [m.data for m in reader.read_messages(str(path), topics=['/diagnostics'])]


def test_a_markers_thread_failure_ends_the_run_with_the_recording_closed(
        tmp_path, monkeypatch, capfd, in_process_run, final_diagnostics):
    def broken(*_):
        raise ArithmeticError('markers injected')

    monkeypatch.setattr('conveyor_twin.output.markers.CellMarkers.build', broken)
    path = tmp_path / 'run.mcap'
    code = in_process_run('--duration', LONG, '--record', str(path))
    summary, _ = _check_run(code, capfd, MARKERS_THREAD, 'markers injected')
    assert summary['steps'] < 600_000  # stopped by the failure, not by the duration
    assert_error_names(final_diagnostics[-1], MARKERS_THREAD)
    info = reader.info(str(path))  # closed cleanly, every step recorded
    assert info['complete']
    assert info['topics']['/clock']['count'] == summary['steps']
    recorded = _recorded_diagnostics(path)
    assert recorded[-1] == final_diagnostics[-1]
    levels = [health_status(d).level for d in recorded]  # OK until the failure, then ERROR
    assert levels == sorted(levels) and set(levels) <= {DiagnosticStatus.OK,
                                                        DiagnosticStatus.ERROR}


def test_a_failing_step_ends_the_run(tmp_path, monkeypatch, capfd, in_process_run,
                                     final_diagnostics):
    from conveyor_twin.output.producers import MicroOutput
    fill = MicroOutput.fill

    def broken(self, frame, inp, commands):
        if inp.step == 1500:
            raise FloatingPointError('step injected')
        fill(self, frame, inp, commands)

    monkeypatch.setattr(MicroOutput, 'fill', broken)
    path = tmp_path / 'run.mcap'
    code = in_process_run('--duration', LONG, '--record', str(path), '--markers-rate', '0')
    summary, _ = _check_run(code, capfd, STEPPING_THREAD, 'step injected')
    assert summary['steps'] == 1500
    assert_error_names(final_diagnostics[-1], STEPPING_THREAD)
    assert reader.info(str(path))['complete']
    recorded = _recorded_diagnostics(path)
    assert len(recorded) == 2 and health_status(recorded[0]).level == DiagnosticStatus.OK
    assert_error_names(recorded[1], STEPPING_THREAD)


def test_a_failing_recorder_writer_ends_the_run(tmp_path, monkeypatch, capfd, in_process_run,
                                                final_diagnostics):
    def disk_full(*_):
        raise OSError(28, 'No space left on device')

    monkeypatch.setattr('conveyor_twin.record._mcapfile.McapFile.flush', disk_full)
    code = in_process_run('--duration', LONG, '--record', str(tmp_path / 'run.mcap'))
    summary, _ = _check_run(code, capfd, WRITER_NAME, 'No space left on device')
    assert 'No space left on device' in summary['recording']['error']
    assert_error_names(final_diagnostics[-1], WRITER_NAME)


class Capture:
    """A sink keeping every diagnostics message of the frames and off the step."""

    def __init__(self) -> None:
        self.diagnostics = []

    def on_frame(self, frame) -> None:
        if frame.diagnostics is not None:
            self.diagnostics.append(frame.diagnostics)

    def on_message(self, topic, stamp_ns, data) -> None:
        if topic is contract.DIAGNOSTICS:
            self.diagnostics.append(data)


def _composed(ros_context, mode=TimeMode.FAST):
    return ComposedTwin(load_cell(), seed=1, mode=mode, context=ros_context, markers_rate=0.0)


def test_a_queued_sink_consumer_failure_is_reported_and_sets_diagnostics_to_error(
        ros_context, capfd):
    twin = _composed(ros_context)
    capture = Capture()
    twin.output.subscribe(capture)

    def consume(frame):
        if frame.step >= 1200:  # (a frame may be dropped when the queue is full)
            raise LookupError('consumer injected')

    sink = QueuedSink(consume, health=twin.output.health, name='test viewer')
    twin.output.subscribe(sink)
    twin.start()
    try:
        assert twin.health.event.wait(WAIT)
        # still stepping: the next periodic diagnostics carry the ERROR too
        assert wait_for(lambda: any(health_status(d).level == DiagnosticStatus.ERROR
                                    for d in capture.diagnostics), WAIT)
    finally:
        twin.stop()
        sink.close()
    assert_error_names(capture.diagnostics[-1], 'test viewer')
    assert [f.name for f in twin.health.failures] == ['test viewer']
    err = capfd.readouterr().err
    assert err.count('test viewer failed: LookupError') == 1 and 'Traceback' in err


def test_an_executor_callback_failure_is_reported(ros_context, monkeypatch, capfd):
    def broken(self, msg):
        raise TypeError('callback injected')

    monkeypatch.setattr(CoordinatorNode, '_on_belt_command', broken)
    twin = _composed(ros_context, mode=TimeMode.LOCKSTEP)
    capture = Capture()
    twin.output.subscribe(capture)
    import rclpy
    node = rclpy.create_node('command_sender', context=ros_context)
    publisher = create_publisher_for_command(node)
    twin.start()
    try:
        assert wait_for(lambda: publisher.get_subscription_count() >= 1, WAIT)
        publisher.publish(BeltCommand(belt='main', speed=0.5))
        assert twin.health.event.wait(WAIT)
    finally:
        twin.stop()
        node.destroy_node()
    assert [f.name for f in twin.health.failures] == [EXECUTOR]
    assert_error_names(capture.diagnostics[-1], EXECUTOR)
    err = capfd.readouterr().err
    assert err.count(f'{EXECUTOR} failed: TypeError') == 1 and 'callback injected' in err


def create_publisher_for_command(node):
    from conveyor_twin.ros.endpoints import message_class
    from conveyor_twin.ros.qos import to_rclpy
    topic = contract.BELT_COMMAND
    return node.create_publisher(message_class(topic.type_name), topic.name,
                                 to_rclpy(topic.qos))


SCALE_NODE_WITH_A_FAILING_CALLBACK = """
import sys
from conveyor_twin.ros import micro_node, scale_node
serve = scale_node.ScaleNode.serve_coordinator
def serve_then_fail(self):
    serve(self)
    self.create_timer(0.05, lambda: 1 / 0)
scale_node.ScaleNode.serve_coordinator = serve_then_fail
sys.exit(micro_node.main(sys.argv))
"""


@pytest.mark.slow
def test_a_scale_node_process_exits_non_zero_when_its_executor_fails(ros_processes):
    args = ros_args('', 1, 'lockstep', 0.0, None, 0.0)
    proc = ros_processes.start([sys.executable, '-c', SCALE_NODE_WITH_A_FAILING_CALLBACK]
                               + args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True)
    _, err = proc.communicate(timeout=WAIT)
    assert proc.returncode == EXIT_BACKGROUND_FAILURE, err[-4000:]
    assert err.count('micro_simulator executor thread failed: ZeroDivisionError') == 1, err
    assert 'Traceback' in err


def _children(pid: int):
    """(pid, command line) of every child process of ``pid``."""
    out = []
    for entry in os.listdir('/proc'):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f'/proc/{entry}/stat').read_bytes()
            cmdline = Path(f'/proc/{entry}/cmdline').read_bytes().replace(b'\0', b' ')
        except OSError:
            continue
        if int(stat[stat.rfind(b')') + 2:].split()[1]) == pid:
            out.append((int(entry), cmdline.decode(errors='replace')))
    return out


class SplitRun:
    """``conveyor-twin run --split`` (realtime, long) and a subscription to its diagnostics."""

    def __init__(self, ros_context, ros_processes) -> None:
        import rclpy
        from conveyor_twin.ros.compat import make_executor, spin_until
        self.received = []
        self.node = rclpy.create_node('diagnostics_probe', context=ros_context)
        create_subscription(self.node, contract.DIAGNOSTICS, self.received.append, raw=True)
        self.executor = make_executor(ros_context)
        self.executor.add_node(self.node)
        self.stop = threading.Event()
        self.spinner = threading.Thread(target=spin_until, args=(self.executor, self.stop),
                                        daemon=True)
        self.spinner.start()
        self.run = ros_processes.start(
            [sys.executable, '-m', 'conveyor_twin.cli', 'run', '--split', '--mode', 'realtime',
             '--duration', LONG, '--quiet', '--json', '--markers-rate', '0'],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    def micro_pid(self) -> int:
        """Wait until the twin publishes diagnostics; return the micro process's id."""
        run, received = self.run, self.received
        assert wait_for(lambda: received or run.poll() is not None, START), 'no diagnostics'
        assert run.poll() is None, run.communicate()[1][-4000:]
        (micro,) = [pid for pid, cmd in _children(run.pid)
                    if 'conveyor_twin.ros.micro_node' in cmd]
        return micro

    def finish(self):
        """Wait for the run's end and an ERROR diagnostics; return (summary, stderr, the
        first ERROR diagnostics' health status)."""
        try:
            out, err = self.run.communicate(timeout=WAIT)
            assert wait_for(lambda: any(health_status(d).level == DiagnosticStatus.ERROR
                                        for d in self.received), WAIT)
        finally:
            self.stop.set()
            self.spinner.join(5.0)
            self.executor.shutdown(timeout_sec=5.0)
            self.node.destroy_node()
        assert self.run.returncode == EXIT_BACKGROUND_FAILURE, err[-4000:]
        error = [d for d in self.received if health_status(d).level == DiagnosticStatus.ERROR][0]
        assert all(health_status(d).level == DiagnosticStatus.OK
                   for d in self.received[:self.received.index(error)])
        summary = json.loads(out.strip().splitlines()[-1])
        assert summary['steps'] < 600_000
        return summary, err, health_status(error)


@pytest.mark.slow
def test_a_split_scale_node_that_stops_answering_is_named_with_its_process_state(
        ros_context, ros_processes):
    split = SplitRun(ros_context, ros_processes)
    micro = split.micro_pid()
    os.kill(micro, signal.SIGSTOP)  # alive, but silent
    try:
        summary, err, status = split.finish()
    finally:
        with contextlib.suppress(ProcessLookupError):  # the run may have killed it
            os.kill(micro, signal.SIGCONT)
    (failure,) = summary['failures']
    assert failure['name'] == STEPPING_THREAD
    assert f'micro_simulator (its process (pid {micro}) is alive) did not answer' \
        in failure['error'] and 'within 10 s' in failure['error'], failure
    assert err.count(f'conveyor_twin: {STEPPING_THREAD} failed:') == 1 and 'Traceback' in err
    assert 'micro_simulator' in status.message and 'is alive' in status.message


@pytest.mark.slow
def test_a_killed_split_scale_node_ends_the_run_with_an_error(ros_context, ros_processes):
    split = SplitRun(ros_context, ros_processes)
    os.kill(split.micro_pid(), signal.SIGKILL)
    summary, err, status = split.finish()
    assert split.run.returncode == EXIT_BACKGROUND_FAILURE, err[-4000:]
    # the parent reports the dead process once, by name, with its exit code and its log's tail
    assert err.count('conveyor_twin: micro_simulator process failed: exited with code -9') \
        == 1, err[-4000:]
    assert 'last lines of its log' in err
    errors = {f['name']: f['error'] for f in summary['failures']}
    assert errors.get('micro_simulator process') == 'exited with code -9 during the run', summary
    assert 'micro_simulator' in status.message  # by the process watch or the step's wait
    assert 'ended during the run' in status.message or 'has exited' in status.message


def test_a_replay_prefetch_failure_is_reported_and_raised(monkeypatch):
    from conveyor_twin.health import Health
    from conveyor_twin.ros import replay

    def broken_schedule(*_, **__):
        yield 0, '/clock', b''
        raise MemoryError('reader injected')

    monkeypatch.setattr(replay, 'schedule', broken_schedule)
    printed = []
    health = Health(printer=printed.append)
    prefetch = replay._Prefetch(None, 0, False, health=health)
    try:
        assert prefetch.get() == (0, 0, '/clock', b'')
        with pytest.raises(MemoryError, match='reader injected'):
            prefetch.get()
    finally:
        prefetch.stop()
    assert [f.name for f in health.failures] == [replay.PREFETCH_THREAD]
    assert len(printed) == 1 and 'Traceback' in printed[0]


def test_a_failing_writer_ends_conveyor_twin_record(tmp_path, monkeypatch, capfd):
    from conveyor_twin.cli import record

    def disk_full(*_):
        raise OSError(28, 'No space left on device')

    monkeypatch.setattr('conveyor_twin.record._mcapfile.McapFile.flush', disk_full)
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:  # without the failure it would record for 600 s
        code = record.main(['-o', str(tmp_path / 'rec.mcap'), '--duration', LONG, '--json'])
    finally:
        for sig, handler in saved.items():
            signal.signal(sig, handler)
    err = capfd.readouterr().err
    assert code == EXIT_BACKGROUND_FAILURE, err[-4000:]
    assert err.count(f'conveyor_twin: {WRITER_NAME} failed: OSError') == 1, err[-4000:]
    assert 'Traceback' in err and 'No space left on device' in err
