"""The actuator faults on a transfer unit (the transfer cell, lockstep, public API plus the
controller of examples/transfer_every_other.py attached in the test process)."""


import numpy as np
import pytest

from test.coord.test_transfer_cell import attach, CELL, lift_history, rising, STROKE, TIMEOUT

pytestmark = pytest.mark.ros
CHUNK = 10
DT = 0.001              # s, the cell's step
LIFT_STEP = 0.1 * DT    # m per step at the transfer's lift speed (0.02 m in 0.2 s)
ENGAGE = 0.01           # m, the transfer's engage height


def test_stuck_down_it_leaves_every_part_on_the_main_line(conveyor_twin_factory):
    twin = conveyor_twin_factory(CELL, seed=1, chunk=CHUNK, timeout=TIMEOUT)
    node = attach(twin)
    fault = twin.inject_fault('actuator_stuck', 'xfer')
    twin.step_until(lambda: len(rising(twin, 'lb_main_out')) >= 2, max_steps=10_000,
                    what='two parts on the main line')
    assert twin.active_faults()[fault].kind == 'actuator_stuck'
    arrived = rising(twin, 'lb_main_in')
    # the first part, meant for the side line, stayed on the main line with the second
    assert rising(twin, 'lb_main_out') == arrived[:2]
    assert twin.edges(name='lb_side') == [] and node.counts['side'] == 0
    history = lift_history(twin)
    assert np.all(history[:, 1] == 0.0)                  # it never moved ...
    assert np.any(history[:, 0] == STROKE)               # ... though raised by the controller
    # the controller raised it for the first part and lowered it when the second arrived
    assert [r.value for r in twin.command_log() if r.target == 'xfer'][:2] == [STROKE, 0.0]
    assert node.counts['main'] == 2 and node.timeouts == 0
    # cleared, it follows its commands again
    twin.clear_fault(fault)
    twin.set_actuator('xfer', STROKE)
    twin.step_until(lambda: twin.actuator('xfer').position == STROKE, max_steps=1000,
                    what='the transfer lifted after the fault was cleared')


def test_slow_it_lifts_at_the_fraction_of_its_speed(conveyor_twin_factory):
    twin = conveyor_twin_factory(CELL, seed=1, chunk=CHUNK, timeout=TIMEOUT)
    twin.inject_fault('actuator_slow', 'xfer', factor=0.5)
    twin.set_actuator('xfer', STROKE)
    twin.step_until(lambda: twin.actuator('xfer').position == STROKE, max_steps=2000,
                    what='the slow transfer reached its stroke')
    actual = lift_history(twin)[:, 1]
    moving = np.flatnonzero(np.diff(actual))
    deltas = np.diff(actual)[moving]
    assert np.allclose(deltas[:-1], 0.5 * LIFT_STEP, rtol=1e-9, atol=1e-12)
    assert moving.size == pytest.approx(STROKE / (0.5 * LIFT_STEP), abs=1)  # 0.4 s, not 0.2 s


def test_offset_above_its_engage_height_it_carries_while_lowered(conveyor_twin_factory):
    twin = conveyor_twin_factory(CELL, seed=1, chunk=CHUNK, timeout=TIMEOUT)
    twin.inject_fault('actuator_offset', 'xfer', offset=0.015)
    twin.step(1)
    state = twin.actuator('xfer')                        # it rises at its lift speed
    assert state.commanded_position == 0.0
    assert state.position == pytest.approx(LIFT_STEP, rel=1e-9)
    [part] = twin.spawn('carton', [1.45], [-0.1], [0.0])
    twin.step(400)                                       # 0.4 s
    # carried sideways at the rollers' speed (the lift ramps up to the offset at its lift
    # speed, so the main belt drives the part for the first 0.1 s)
    p = twin.part(int(part))
    assert p is not None and p['y'] > 0.0 and p['vy'] == pytest.approx(0.5, abs=0.01)
    assert twin.actuator('xfer')[:2] == (0.0, 0.015)    # still commanded down
