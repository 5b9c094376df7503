"""The bench's machine figures: CPU stolen by the hypervisor from two /proc/stat readings."""

from conveyor_twin.bench.twin import cpu_times, steal_percent


def test_steal_share_of_all_cpu_time():
    # user nice system idle iowait irq softirq steal (jiffies)
    before = [100, 0, 50, 800, 0, 0, 0, 50]
    after = [300, 0, 100, 1350, 0, 0, 0, 150]  # 900 more jiffies, 100 of them stolen
    assert steal_percent(before, after) == round(100 * 100 / 900, 2)
    assert steal_percent(None, after) is None and steal_percent(before, before) is None


def test_cpu_times_reads_this_machine():
    times = cpu_times()
    assert times is None or (len(times) >= 8 and all(t >= 0 for t in times))
