"""The bench's machine figures: CPU stolen by the hypervisor, clock gaps of a reading loop, the
paced floor loop and the twin's overruns as a ratio to it."""

import numpy as np

from conveyor_twin.bench.cpu import cpu_times, steal_percent


def test_steal_share_of_all_cpu_time():
    # user nice system idle iowait irq softirq steal (jiffies)
    before = [100, 0, 50, 800, 0, 0, 0, 50]
    after = [300, 0, 100, 1350, 0, 0, 0, 150]  # 900 more jiffies, 100 of them stolen
    assert steal_percent(before, after) == round(100 * 100 / 900, 2)
    assert steal_percent(None, after) is None and steal_percent(before, before) is None


def test_cpu_times_reads_this_machine():
    times = cpu_times()
    assert times is None or (len(times) >= 8 and all(t >= 0 for t in times))


def test_clock_gaps_are_classified_by_length():
    from conveyor_twin.bench.host import classify
    ns = np.array([0.6e6, 0.9e6, 1.5e6, 3e6, 7e6, 50e6], dtype=np.int64)
    counts = classify(ns)
    assert counts == {'0.5-1 ms': 2, '1-2 ms': 1, '2-5 ms': 1, '5-20 ms': 1, '>20 ms': 1,
                      'over_1ms': 4}


def test_clock_gaps_see_a_sleep_of_the_reading_thread():
    import threading
    import time

    from conveyor_twin.bench.host import clock_gaps
    # a second thread holding the GIL for ~20 ms stops the reading loop for about that long
    hold = threading.Thread(target=lambda: (time.sleep(0.05), sum(range(3_000_000))))
    hold.start()
    gaps = clock_gaps(0.5)
    hold.join()
    assert gaps.size >= 1 and gaps.max() > 2e6


def test_paced_floor_keeps_every_deadline_it_counts():
    from conveyor_twin.bench.host import paced_floor
    result = paced_floor(0.2)
    assert result['steps'] == 200 and result['period_ns'] == 1_000_000
    assert 0 <= result['overruns'] <= result['steps']
    assert result['policy'] in ('SCHED_FIFO', 'normal (SCHED_FIFO refused)')


def test_paced_floor_counts_an_impossible_period_as_overruns():
    from conveyor_twin.bench.host import paced_floor
    # a 1 ns period: every deadline has passed before the loop looks at the clock again
    result = paced_floor(1e-4, period_ns=1, priority=0)
    assert result['steps'] == 100_000 and result['overruns'] > 90_000
    assert result['policy'] == 'normal'


def test_the_floor_loop_can_work_a_calibrated_time_per_step():
    import pytest

    from conveyor_twin.bench.host import paced_floor
    result = paced_floor(0.2, work_ns=300_000)
    # whole passes over the array, calibrated to the nearest pass of the time asked for
    assert result['steps'] == 200 and result['work_passes'] >= 1
    assert 150_000 <= result['work_ns'] <= 450_000
    assert 0 <= result['slow_work'] <= result['steps']
    assert paced_floor(0.01)['work_passes'] == 0
    with pytest.raises(RuntimeError, match='WORK_NS in'):   # no step can hold a whole period
        paced_floor(0.01, work_ns=1_000_000)


def test_twin_overruns_as_a_ratio_to_the_working_floor():
    from conveyor_twin.bench.twin import compare_to_floor
    before = {'overruns': 2, 'duration_s': 30.0, 'working': {
        'overruns': 10, 'duration_s': 30.0, 'work_ns': 300_000}}
    after = {'overruns': 4, 'duration_s': 30.0, 'working': {
        'overruns': 14, 'duration_s': 30.0, 'work_ns': 300_000}}
    figures = {'overruns_in_window': 48, 'window_s': 60.0}
    compare_to_floor(figures, before, after)
    assert figures['overruns_vs_floor'] == 8.0
    assert figures['floor']['working_overruns_per_min'] == 24.0
    assert figures['floor']['working_work_ms'] == 0.3
    assert figures['overruns_vs_working_floor'] == 2.0


def test_twin_overruns_as_a_ratio_to_the_floor():
    from conveyor_twin.bench.twin import compare_to_floor
    before = {'overruns': 2, 'duration_s': 30.0}
    after = {'overruns': 4, 'duration_s': 30.0}
    figures = {'overruns_in_window': 12, 'window_s': 60.0}
    compare_to_floor(figures, before, after)
    assert figures['floor']['overruns_per_min'] == 6.0 and figures['overruns_per_min'] == 12.0
    assert figures['overruns_vs_floor'] == 2.0
    quiet = {'overruns_in_window': 3, 'window_s': 60.0}
    compare_to_floor(quiet, {'overruns': 0, 'duration_s': 30.0}, None)
    assert quiet['overruns_vs_floor'] is None and quiet['floor']['overruns_per_min'] == 0.0
