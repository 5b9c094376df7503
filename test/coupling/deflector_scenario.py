"""The deflector jam of the scale validation, run once per (scale, seed, perturbation) per process.

Default cell, 2400 spacers at 500 parts/s, one zone over the whole belt: ``micro`` for pure micro,
``auto`` for multi-scale (tiles 0.2 m on a 2 cm grid, to macro above 3000 parts/m^2, to micro
below 1000, dwell 0.2 s, sensor windows 0.05 m, free flow kept micro below a mean slip of 0.1 of
the belt speed). The macro collision operator is the default cell's (``epsilon`` 2.0 m/s).
20000 steps of 1 ms. Each run records every light-barrier edge, and every 0.1 s the queue in
front of the deflector and the parts out through the exit, measured the same way at both
scales. ``test_validation.py`` and ``test_sensor_windows.py`` share the runs (a cache per
process), and docs/validation.md reports the same quantities over seeds 1..8.
"""

import functools
from typing import Dict, List, Tuple

import numpy as np
import yaml

from conveyor_twin.cell.loader import cell_from_mapping, default_cell_text
from conveyor_twin.coord.assembly import build_twin

PARTS = 2400
STEPS = 20000
SAMPLE_STEPS = 100
# Upstream of the deflector's gap end (x = 3.1): the queue box [m].
DEFLECTOR_BOX = (2.2, -0.25, 3.1, 0.25)
# Light barriers of the default cell, in its order.
INFEED, AFTER_DEFLECTOR, EXIT = 0, 1, 2
# Mean slip [fraction of the belt speed] below which an ``auto`` tile is free flow, stays micro.
FREE_FLOW_SLIP = 0.1
# Sub-physical perturbations of pure micro: the belt speed in the 12th digit; every spawn
# position moved 1e-9 m along the belt.
PERTURBATIONS = ('belt_speed_1e-12', 'spawn_shift_1e-9m')


def deflector_cell(policy: str, perturbation: str = ''):
    """Return the scenario's cell for zone ``policy`` (``micro`` or ``auto``)."""
    d = yaml.safe_load(default_cell_text())
    d['sources'][0]['rate'] = 500.0
    d['sources'][0]['max_parts'] = PARTS
    d['zones'] = [{'name': 'belt', 'policy': policy, 'region': [0.0, -0.25, 6.0, 0.25],
                   'resolution': 0.02,
                   'auto': {'tile': 0.2, 'to_macro_density': 3000.0,
                            'to_micro_density': 1000.0, 'min_dwell': 0.2,
                            'sensor_margin': 0.05, 'free_flow_slip': FREE_FLOW_SLIP}}]
    if perturbation == 'belt_speed_1e-12':
        d['belts'][0]['speed'] = 0.5 * (1.0 + 1e-12)
    elif perturbation == 'spawn_shift_1e-9m':
        r = d['sources'][0]['region']
        d['sources'][0]['region'] = [r[0] + 1e-9, r[1], r[2] + 1e-9, r[3]]
    elif perturbation:
        raise ValueError(f'unknown perturbation {perturbation!r}')
    return cell_from_mapping(d)


@functools.lru_cache(maxsize=None)
def deflector_run(policy: str, seed: int, perturbation: str = '') -> Dict[str, object]:
    """Run the scenario; return ``edges`` (barrier, blocked, time [ns]) in order, ``counts``
    per barrier, ``queue`` and ``left`` [parts] every 0.1 s, the tile ``switches``, the
    largest ledger residual (the ledger is checked every step: BalanceError otherwise) and the
    largest density [parts/m^2, summed over cells] seen in sensor-window cells."""
    cell = deflector_cell(policy, perturbation)
    built = build_twin(cell, seed=seed)
    twin, micro, macro = built.twin, built.micro, built.macro
    coupling = twin.stages[-1]
    coupling.check = True
    edges: List[Tuple[int, bool, int]] = []
    queue: List[float] = []
    left: List[float] = []
    window_mass = 0.0
    x0, y0, x1, y1 = DEFLECTOR_BOX
    for k in range(STEPS):
        twin.step(1)
        b, blocked, t, _ = micro.edges()
        edges.extend(zip(b.tolist(), blocked.tolist(), t.tolist()))
        if (k + 1) % SAMPLE_STEPS == 0:
            v = micro.sim.parts_view()
            q = float(((v.x >= x0) & (v.x < x1) & (v.y >= y0) & (v.y < y1)).sum())
            out = float(micro.sim.left[0])
            if coupling.enabled:
                q += macro.grids[0].region_parts(DEFLECTOR_BOX)
                out += coupling.left_macro
                region = coupling.regions[0]
                in_windows = float(region.sim.density[region.closed == 1].sum())
                window_mass = max(window_mass, in_windows)
            queue.append(q)
            left.append(out)
    return {'edges': edges, 'counts': micro.barrier_edge_count().astype(int).tolist(),
            'queue': np.array(queue), 'left': np.array(left),
            'switches': coupling.regions[0].tiles.switches if coupling.enabled else 0,
            'residual': coupling.max_residual if coupling.enabled else 0.0,
            'window_mass': window_mass}


def barrier_edges(run: Dict[str, object], index: int) -> List[Tuple[bool, int]]:
    """Return the (blocked, time [ns]) edges of barrier ``index`` in ``run``."""
    return [(blocked, t) for b, blocked, t in run['edges'] if b == index]


def mean_exit_time(left: np.ndarray) -> float:
    """Mean time [s] at which the parts leave: the integral of the parts not yet out."""
    return float((PARTS - left).sum()) * SAMPLE_STEPS * 1e-3 / PARTS


def exit_time(left: np.ndarray, fraction: float) -> float:
    """Time [s] at which ``fraction`` of the parts have left."""
    return (int(np.argmax(left >= fraction * PARTS)) + 1) * SAMPLE_STEPS * 1e-3


def plateau_rate(left: np.ndarray) -> float:
    """Exit rate [parts/s] while the 10 % .. 90 % of the parts leave."""
    return 0.8 * PARTS / (exit_time(left, 0.9) - exit_time(left, 0.1))
