"""Diagnostics: once per 1000 steps (1 Hz of sim time) with every figure the contract names."""

from diagnostic_msgs.msg import DiagnosticArray
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.ros.compose import ComposedTwin
from conveyor_twin.ros.qos import SLOW_QOS
from conveyor_twin.testing.driver import Driver, TIMEOUT
from conveyor_twin.testing import wait_for

pytestmark = pytest.mark.ros
KEYS = {'step', 'mode', 'step_time_mean_ms', 'step_time_p99_ms', 'step_time_max_ms',
        'overruns', 'slowest_step_ms', 'slowest_step_parts_ms', 'slowest_step_cpu_ms',
        'latest_wake_ms',
        'real_time_factor', 'rejected_commands', 'last_rejection', 'publish_failures',
        'micro_entered', 'micro_left', 'micro_in_flight',
        'macro_entered', 'macro_left', 'macro_in_flight'}


def test_diagnostics_every_sim_second_with_step_times_overruns_rtf_rejections_balance(
        ros_context):
    twin = ComposedTwin(load_cell(), seed=2, mode=TimeMode.LOCKSTEP, context=ros_context,
                        markers_rate=0.0)
    twin.start()
    driver = Driver(ros_context, name='diag_probe')
    received = []
    driver.probe.create_subscription(DiagnosticArray, 'diagnostics', received.append, SLOW_QOS)
    try:
        assert driver.wait_connected()
        assert wait_for(lambda: driver.probe.count_publishers('diagnostics') > 0, TIMEOUT,
                        driver.executor)
        driver.step(1999)
        assert wait_for(lambda: len(received) >= 1, TIMEOUT, driver.executor)
        driver.step(1)
        assert wait_for(lambda: len(received) >= 2, TIMEOUT, driver.executor)
        stamps = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in received]
        assert stamps == [(1, 0), (2, 0)]
        status = received[-1].status[0]
        values = {kv.key: kv.value for kv in status.values}
        assert KEYS <= set(values), sorted(KEYS - set(values))
        assert values['step'] == '2000' and values['mode'] == 'lockstep'
        mean, p99, peak = (float(values[f'step_time_{k}_ms']) for k in ('mean', 'p99', 'max'))
        assert 0.0 < mean <= peak and p99 <= peak
        assert values['overruns'] == '0' and values['rejected_commands'] == '0'
        # the slowest recent step, and its time per part of the step, largest first
        parts = {label: float(ms) for label, ms in
                 (item.rsplit(' ', 1) for item in values['slowest_step_parts_ms'].split(', '))}
        assert set(parts) == {'commands', 'micro', 'macro', 'hand-over', 'outputs'}
        assert list(parts.values()) == sorted(parts.values(), reverse=True)
        assert float(values['slowest_step_ms']) == pytest.approx(sum(parts.values()), abs=0.003)
        assert 0.0 < float(values['slowest_step_cpu_ms'])
        assert float(values['slowest_step_ms']) > 0.0
        assert values['latest_wake_ms'] == '0.0000'  # lockstep: no step waits for a deadline
        float(values['real_time_factor'])
        # part balance: what entered is in flight or has left
        entered = float(values['micro_entered']) + float(values['macro_entered'])
        assert entered > 0
        assert entered == pytest.approx(
            float(values['micro_in_flight']) + float(values['micro_left'])
            + float(values['macro_in_flight']) + float(values['macro_left']))
    finally:
        driver.close()
        twin.stop()
