"""The harness and kernel compiles: the first compile (or cache load) of the kernels is waited
for before the twin starts, with its own budget, so it never counts against ``timeout``; a
compile over that budget ends with a clear error and the process still exits cleanly."""

import subprocess
import sys
import textwrap
import threading

import pytest

from conveyor_twin.testing import kernels, LockstepTwin, quiet_cell, TwinTimeoutError

pytestmark = pytest.mark.ros

STEP_TIMEOUT = 5.0  # s, the harness's timeout in these tests


def _kernel_threads():
    return [t for t in threading.enumerate() if t.name == 'conveyor_twin-kernels']


def test_a_compile_longer_than_the_timeout_is_not_counted_against_it(monkeypatch, capfd):
    real = kernels._warm
    waited = []

    def slow_compile(cell, seed):
        real(cell, seed)
        # a compile on a loaded machine: longer than the step timeout
        threading.Event().wait(2.5 * STEP_TIMEOUT)
        waited.append(True)

    monkeypatch.setattr(kernels, '_warm', slow_compile)
    with LockstepTwin(quiet_cell(), timeout=STEP_TIMEOUT) as twin:
        assert waited == [True]
        assert twin.step(20) == 20                     # the first steps, in time
    err = capfd.readouterr().err
    assert 'compiling the simulation kernels' in err
    assert f'not counted against the step timeout of {STEP_TIMEOUT:g} s' in err


def test_a_compile_over_its_budget_ends_with_an_error_naming_it(monkeypatch):
    release = threading.Event()
    monkeypatch.setattr(kernels, '_warm', lambda cell, seed: release.wait(300.0))
    monkeypatch.setattr(kernels, 'COMPILE_BUDGET', 0.2)
    try:
        with pytest.raises(TwinTimeoutError, match='did not finish compiling within 0.2 s'):
            LockstepTwin(quiet_cell(), timeout=STEP_TIMEOUT)
    finally:
        release.set()
        for thread in _kernel_threads():
            thread.join(300.0)
    assert not _kernel_threads()


def test_a_warm_up_failure_is_raised_to_the_test(monkeypatch):
    def broken(cell, seed):
        raise RuntimeError('kernel broke')

    monkeypatch.setattr(kernels, '_warm', broken)
    with pytest.raises(RuntimeError, match='kernel broke'):
        LockstepTwin(quiet_cell(), timeout=STEP_TIMEOUT)


def test_exit_waits_for_a_compile_in_flight():
    from numba.core.compiler_lock import global_compiler_lock
    held, release = threading.Event(), threading.Event()

    def compiling():
        with global_compiler_lock:
            held.set()
            release.wait(300.0)

    thread = threading.Thread(target=compiling, daemon=True)
    thread.start()
    assert held.wait(300.0)
    try:
        assert kernels.wait_for_compiles(budget=0.1) is False
    finally:
        release.set()
    assert kernels.wait_for_compiles(budget=300.0) is True
    thread.join(300.0)


def test_a_process_left_compiling_after_the_budget_exits_cleanly(tmp_path):
    script = textwrap.dedent('''
        from numba import njit
        from conveyor_twin.cell import load_cell
        from conveyor_twin.testing import kernels
        from conveyor_twin.testing.errors import TwinTimeoutError

        def compile_now(cell, seed):
            @njit(cache=False)
            def f(x):
                return sum([x * i for i in range(10)])
            f(1.5)

        kernels.COMPILE_BUDGET = 0.0
        kernels.NOTICE_AFTER = 0.0
        try:
            kernels.ready_kernels(load_cell(), 0, timeout=1.0, warm=compile_now)
        except TwinTimeoutError as exc:
            print('timed out:', exc)
    ''')
    done = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                          timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert 'terminate called' not in done.stderr
    assert 'timed out: the simulation kernels did not finish compiling' in done.stdout
