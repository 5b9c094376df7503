"""The pacer's requests to the operating system: the wake-up latency request and the sleep
that keeps the interpreter lock."""

import struct
import sys
import threading
import time

import pytest

from conveyor_twin.coord import latency
from conveyor_twin.coord.latency import LATENCY_ENV, sleep_holding_gil, WakeLatencyRequest
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import Health


def test_request_writes_zero_and_holds_the_device_until_released(tmp_path, monkeypatch):
    device = tmp_path / 'cpu_dma_latency'
    device.write_bytes(b'')
    monkeypatch.setattr(latency, 'CPU_LATENCY_DEVICE', str(device))
    monkeypatch.setenv(LATENCY_ENV, '1')
    request = WakeLatencyRequest()
    assert request.acquire() and request.held and request.status == 'held'
    assert struct.unpack('i', device.read_bytes()) == (0,)
    assert request.acquire()  # a second acquire keeps the one request
    assert device.read_bytes() == struct.pack('i', 0)
    request.release()
    assert not request.held and request.status == 'released'


def test_refused_request_names_the_device_and_the_reason(tmp_path, monkeypatch):
    missing = tmp_path / 'no_such_device'
    monkeypatch.setattr(latency, 'CPU_LATENCY_DEVICE', str(missing))
    monkeypatch.setenv(LATENCY_ENV, '1')
    request = WakeLatencyRequest()
    assert not request.acquire()
    assert not request.held
    assert str(missing) in request.status and request.status.startswith('refused')


@pytest.mark.parametrize('setting', [None, '0', 'yes'])
def test_request_is_off_unless_asked_for(tmp_path, monkeypatch, setting):
    device = tmp_path / 'cpu_dma_latency'
    device.write_bytes(b'')
    monkeypatch.setattr(latency, 'CPU_LATENCY_DEVICE', str(device))
    if setting is None:
        monkeypatch.delenv(LATENCY_ENV, raising=False)
    else:
        monkeypatch.setenv(LATENCY_ENV, setting)
    request = WakeLatencyRequest()
    assert not request.acquire()
    assert request.status.startswith('off') and LATENCY_ENV in request.status
    assert device.read_bytes() == b''


@pytest.mark.parametrize('mode', [TimeMode.REALTIME, TimeMode.FAST])
def test_runner_holds_the_request_only_while_it_paces_in_realtime(tmp_path, monkeypatch, mode):
    device = tmp_path / 'cpu_dma_latency'
    device.write_bytes(b'')
    monkeypatch.setattr(latency, 'CPU_LATENCY_DEVICE', str(device))
    monkeypatch.setenv(LATENCY_ENV, '1')
    held = []
    twin = _CountingTwin(on_step=lambda: held.append(runner.pacer.latency_request.held))
    runner = Runner(twin, mode, max_steps=20)
    runner.tuned = runner.warm_up = False
    runner.start()
    assert runner.wait(30.0)
    assert runner.error is None and len(held) == 20
    assert all(held) if mode is TimeMode.REALTIME else not any(held)
    assert not runner.pacer.latency_request.held  # withdrawn when the loop ends
    assert device.read_bytes() == (struct.pack('i', 0) if mode is TimeMode.REALTIME else b'')


class _CountingTwin:
    """The least a runner steps: ``step``, ``dt_ns``, ``health``."""

    dt_ns = 1_000_000

    def __init__(self, on_step) -> None:
        self.health = Health()
        self.on_step = on_step

    def step(self, n: int = 1) -> None:
        for _ in range(n):
            self.on_step()


def test_sleep_reaches_its_deadline():
    for delay_ns in (0, 100_000, 2_000_000):
        deadline = time.monotonic_ns() + delay_ns
        sleep_holding_gil(deadline)
        assert time.monotonic_ns() >= deadline


@pytest.mark.skipif(latency._SLEEPER is None, reason='clock_nanosleep is not available')
def test_sleep_keeps_the_interpreter_lock_that_time_sleep_gives_away():
    """A thread that counts in Python advances while ``time.sleep`` waits and not while
    ``sleep_holding_gil`` does (a long switch interval: no forced hand-over either way)."""
    count = [0]
    stop = threading.Event()

    def counter():
        while not stop.is_set():
            count[0] += 1

    interval = sys.getswitchinterval()
    sys.setswitchinterval(0.5)
    thread = threading.Thread(target=counter, daemon=True)
    thread.start()
    try:
        while count[0] == 0:  # the counter runs
            time.sleep(0.001)
        before = count[0]
        sleep_holding_gil(time.monotonic_ns() + 50_000_000)
        held = count[0] - before
        before = count[0]
        time.sleep(0.05)
        released = count[0] - before
    finally:
        stop.set()
        sys.setswitchinterval(interval)
        thread.join(5.0)
    assert held == 0
    assert released > 0
