"""The figures of one ``bench twin`` window from the twin's ``diagnostics`` (1 Hz): overruns,
step times, and where the late steps come from."""

from typing import Dict, List

import numpy as np

#: A late second's slowest step counts as waiting for the CPU when the stepping thread ran for
#: less than this share of it.
WORKED_SHARE = 0.5


def window_figures(diagnostics: List[Dict[str, str]]) -> Dict[str, object]:
    """Return the window's figures from the twin's diagnostics (one per second): overruns,
    step times, parts in flight and :func:`late_steps_by_cause` ({} with fewer than two)."""
    if len(diagnostics) < 2:
        return {}
    first, last = diagnostics[0], diagnostics[-1]
    return {
        'overruns_in_window': int(last['overruns']) - int(first['overruns']),
        'diagnostics_messages': len(diagnostics),
        'step_time_mean_ms_median': float(np.median(
            [float(d['step_time_mean_ms']) for d in diagnostics])),
        'step_time_p99_ms_max': max(float(d['step_time_p99_ms']) for d in diagnostics),
        'step_time_max_ms_max': max(float(d['step_time_max_ms']) for d in diagnostics),
        'micro_in_flight': [int(float(diagnostics[0].get('micro_in_flight', 0))),
                            int(float(last.get('micro_in_flight', 0)))],
        **late_steps_by_cause(diagnostics),
    }


def late_steps_by_cause(diagnostics: List[Dict[str, str]], period_ms: float = 1.0
                        ) -> Dict[str, object]:
    """Where the late steps come from: each second of the window with an overrun, counted by
    its slowest step: ``started late`` if even that step fit in ``period_ms`` (so a late one
    began after its deadline: the thread resumed late, ``latest_wake_ms``), ``waited for the
    CPU`` if the stepping thread ran less than :data:`WORKED_SHARE` of that step's time (the
    machine ran something else), else the part of the step (``slowest_step_parts_ms``:
    commands, each stage, outputs) that took most of it; and the slowest step of the window
    with its parts and CPU time, and the latest wake-up [ms]."""
    late: Dict[str, int] = {}
    slowest = max(diagnostics, key=lambda d: float(d.get('slowest_step_ms', 0.0)))
    for before, now in zip(diagnostics, diagnostics[1:]):
        parts = now.get('slowest_step_parts_ms', '')
        if int(now['overruns']) <= int(before['overruns']) or not parts:
            continue
        if float(now['slowest_step_ms']) < period_ms:
            cause = 'started late'
        elif float(now['slowest_step_cpu_ms']) < WORKED_SHARE * float(now['slowest_step_ms']):
            cause = 'waited for the CPU'
        else:
            cause = parts.split(', ')[0].rsplit(' ', 1)[0]
        late[cause] = late.get(cause, 0) + 1
    return {'late_seconds_by_cause': late,
            'slowest_step_ms': float(slowest.get('slowest_step_ms', 0.0)),
            'slowest_step_cpu_ms': float(slowest.get('slowest_step_cpu_ms', 0.0)),
            'slowest_step_parts_ms': slowest.get('slowest_step_parts_ms', ''),
            'latest_wake_ms': max(float(d.get('latest_wake_ms', 0.0)) for d in diagnostics)}
