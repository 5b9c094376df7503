"""The machine's CPU accounting, read around a benchmark: how much time the hypervisor took."""

from typing import List, Optional


def cpu_times() -> Optional[List[int]]:
    """Return the machine's aggregate CPU times (``/proc/stat`` line ``cpu``, jiffies), or
    None where there is no such file."""
    try:
        with open('/proc/stat') as f:
            return [int(v) for v in f.readline().split()[1:]]
    except (OSError, ValueError):
        return None


def steal_percent(before: Optional[List[int]], after: Optional[List[int]]) -> Optional[float]:
    """Return the share of CPU time the hypervisor gave to others between two
    :func:`cpu_times` readings (``steal``, the 8th field) [%], or None if unknown."""
    if not before or not after or len(before) < 8:
        return None
    total = sum(after[:8]) - sum(before[:8])
    return round(100.0 * (after[7] - before[7]) / total, 2) if total > 0 else None
