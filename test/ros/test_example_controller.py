"""examples/stop_on_barrier.py as its own process against a lockstep twin, public API only."""

from pathlib import Path
import sys

import pytest

from conveyor_twin.testing import quiet_cell

pytestmark = pytest.mark.ros
EXAMPLE = Path(__file__).resolve().parents[2] / 'examples' / 'stop_on_barrier.py'
CHUNK = 5          # steps per step call: the controller reacts within this many
MS = 1_000_000     # [ns]


def test_stop_on_barrier_stops_and_restarts_the_belt(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), seed=3, chunk=CHUNK)
    twin.start_controller([sys.executable, str(EXAMPLE), '--ros-args',
                           '-p', 'barrier:=lb_infeed', '-p', 'belt:=main'])
    twin.wait_for_node('stop_on_barrier', subscribes=['light_barrier_edges', 'light_barriers'],
                       publishes=['belt_command'])
    twin.spawn('spacer', [1.8], [0.0])

    def sent() -> list:
        return [r.value for r in twin.command_log() if r.target == 'main']

    twin.step_until(lambda: twin.edges(name='lb_infeed'), max_steps=2000,
                    what='the part reaches lb_infeed')
    edge = twin.edges(name='lb_infeed')[0]
    assert edge.blocked
    twin.wait_until(lambda: sent() == [0.0], what='the controller stops the belt')
    twin.step_until(lambda: twin.time_ns >= edge.time_ns + 500 * MS, max_steps=600)
    twin.wait_until(lambda: sent() == [0.0, 0.5], what='the controller restarts the belt')
    twin.step(300)

    belts = [(b.stamp_ns, b.commanded, b.actual) for b in twin.belt_history('main')]
    stop_ns = next(t for t, commanded, _ in belts if commanded == 0.0)
    restart_ns = next(t for t, commanded, _ in belts if t > stop_ns and commanded > 0.0)
    assert 0 < stop_ns - edge.time_ns <= (2 * CHUNK + 1) * MS
    # the belt actually stopped (speed ramps down to 0) and ran again after the pause
    assert any(actual == 0.0 for t, _, actual in belts if stop_ns <= t < restart_ns)
    assert 500 * MS <= restart_ns - edge.time_ns <= (500 + 2 * CHUNK + 1) * MS
    assert twin.belt('main') == pytest.approx((0.5, 0.5))
    assert twin.parts().x[0] > 2.0  # the part went on through the barrier
    assert all(r.result.accepted for r in twin.command_log())
