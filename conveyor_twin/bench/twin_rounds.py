"""The summary of ``bench twin --rounds N``: per layout or Foxglove variant, the twin/floor
overrun ratio of every round and their median, the messages lost per stream, the load."""

from typing import Dict, List

import numpy as np

from conveyor_twin import contract

#: The streams measured, as :mod:`conveyor_twin.bench.twin` names them.
STREAMS = tuple(t.name for t in (contract.PARTS, contract.LIGHT_BARRIERS, contract.BELT_STATES,
                                 contract.ACTUATOR_STATES, contract.CLOCK))
STEP_NS = 1_000_000


def variant_of(figures: Dict[str, object]) -> str:
    """Return the name of a window's layout or Foxglove variant (``composed``, ``split``,
    ``composed, Foxglove view``, ...)."""
    fox = figures.get('foxglove')
    return f"{figures['layout']}, Foxglove {fox}" if fox else str(figures['layout'])


def rounds_summary(results: List[Dict[str, object]]) -> Dict[str, Dict[str, object]]:
    """Return, per layout or Foxglove variant, the twin/floor ratio of every round and their
    median, the twin's and the floor's overruns per minute, the messages lost per stream over
    all rounds and the load averages (1 min) of the windows."""
    out: Dict[str, Dict[str, object]] = {}
    for figures in results:
        v = out.setdefault(variant_of(figures), {
            'ratios': [], 'twin_overruns_per_min': [], 'floor_overruns_per_min': [],
            'working_ratios': [],
            'lost': {t: 0 for t in STREAMS}, 'load_average': [], 'errors': 0})
        v['load_average'].append(figures.get('load_average'))
        if 'error' in figures:
            v['errors'] += 1
            continue
        v['ratios'].append(figures.get('overruns_vs_floor'))
        v['twin_overruns_per_min'].append(figures.get('overruns_per_min'))
        v['floor_overruns_per_min'].append((figures.get('floor') or {}).get('overruns_per_min'))
        if 'overruns_vs_working_floor' in figures:
            v['working_ratios'].append(figures['overruns_vs_working_floor'])
        expected = int(float(figures.get('window_s', 0.0)) * 1e9 / STEP_NS)
        for topic, stream in figures.get('streams', {}).items():
            # a stream that delivered fewer than two messages lost (nearly) all of the window's
            lost = (int(stream['lost']) if 'lost' in stream
                    else max(expected - int(stream.get('messages', 0)), 0))
            v['lost'][topic] = v['lost'].get(topic, 0) + lost
    for v in out.values():
        finite = [r for r in v['ratios'] if r is not None]
        v['median_ratio'] = float(np.median(finite)) if finite else None
        finite = [r for r in v['working_ratios'] if r is not None]
        v['median_working_ratio'] = float(np.median(finite)) if finite else None
        v['lost_total'] = sum(v['lost'].values())
    return out


def print_rounds(summary: Dict[str, Dict[str, object]]) -> None:
    """Print :func:`rounds_summary`: one line per variant, and its losses."""
    for variant, v in summary.items():
        ratios = ', '.join('n/a' if r is None else f'{r:.2f}' for r in v['ratios'])
        median = v['median_ratio']
        print(f"{variant}: twin / floor overruns per round [{ratios}], median "
              f"{'n/a (the floor saw no overrun)' if median is None else f'{median:.2f}'}; "
              f"twin {v['twin_overruns_per_min']} per min, floor "
              f"{v['floor_overruns_per_min']} per min; load average {v['load_average']}")
        if v['working_ratios']:
            per_round = ', '.join('n/a' if r is None else f'{r:.2f}' for r in v['working_ratios'])
            working = v['median_working_ratio']
            print(f"  twin / floor loop working as long as a step, per round [{per_round}], "
                  f"median {'n/a' if working is None else f'{working:.2f}'}")
        lost = ', '.join(f'{t} {n}' for t, n in v['lost'].items())
        print(f"  lost messages, all rounds: {lost} (total {v['lost_total']})"
              + (f"; {v['errors']} window(s) without a result" if v['errors'] else ''))
