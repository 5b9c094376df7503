"""The cell processes of a plant, supervised (no ROS): a process that ends before its cell is
done is reported once per run with its exit status and last output, started again while it
has restarts left, then left dead while the others run on."""

import io
import sys

from conveyor_twin.health import Health
from conveyor_twin.plant.supervisor import CellProcesses, describe_status
from conveyor_twin.testing.ros_env import wait_for

TIMEOUT = 120.0     # s, a bound for a loaded machine


def crashing(text: str, code: int) -> list:
    return [sys.executable, '-c', f'import sys; print({text!r}); print("{{\\"cell\\": 1}}"); '
            f'sys.exit({code})']


def test_a_dying_cell_is_reported_restarted_then_left_dead():
    health, out = Health(printer=lambda _: None), io.StringIO()
    sleeper = [sys.executable, '-c', 'import time; time.sleep(600)']
    cells = CellProcesses({'a': sleeper, 'b': crashing('out of parts', 4)}, health=health,
                          restarts=1, echo=out)
    cells.start()
    try:
        died = []
        assert wait_for(lambda: died.extend(cells.watch(lambda name: False)) or
                        died == ['b', 'b'], TIMEOUT), (died, out.getvalue())
        assert cells.dead == ['b'] and cells.restarts() == {'a': 0, 'b': 1}
        assert cells.cells['a'].poll() is None            # the other cell runs on
        assert [f.name for f in health.failures] == ["cell 'b' process (run 1)",
                                                     "cell 'b' process (run 2)"]
        assert health.failures[0].error == 'exit status 4; last output: out of parts'
        text = out.getvalue()
        assert "cell 'b' died (exit status 4); its last output:\n  | out of parts" in text
        assert "starting cell 'b' again (restart 1 of 1)" in text
        assert "cell 'b' stays dead; the other cells run on" in text
        assert '[b] out of parts' in text and cells.cells['b'].summary == {'cell': 1}
    finally:
        cells.stop(5.0)
    assert cells.cells['a'].poll() is not None


def test_a_cell_that_ends_done_with_status_0_is_not_a_death():
    health = Health(printer=lambda _: None)
    cells = CellProcesses({'a': crashing('bye', 0)}, health=health, echo=io.StringIO())
    cells.start()
    try:
        assert wait_for(lambda: cells.cells['a'].poll() is not None, TIMEOUT)
        assert cells.watch(lambda name: True) == [] and health.ok
    finally:
        cells.stop(5.0)


def test_exit_statuses_read_as_signals():
    assert describe_status(-9) == '-9 (killed by SIGKILL)'
    assert describe_status(3) == '3'
