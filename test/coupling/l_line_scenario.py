"""The queue in the bend of the L-shaped line, run once per (scale, seed) per process.

``conveyor_twin/cell/examples/l_line.yaml`` with 160 cans fed at 10 parts/s; the outfeed is
stopped for the first 8 s, so the cans queue from its start back into the bend, then runs
again. One zone over the whole line: ``micro`` for pure micro, ``auto`` for multi-scale (the
example's tiles: 0.25 m on a 2 cm grid, to macro above 120 parts/m^2, to micro below 50).
35000 steps of 1 ms, the ledger checked every step. Every 0.1 s: the queue (the parts in the
bend's box) and the parts out through the exit, measured the same way at both scales.
``test_l_line_validation.py`` uses the runs; docs/validation.md reports them over seeds 1..8.
"""

import functools
from pathlib import Path
from typing import Dict

import numpy as np
import yaml

from conveyor_twin.cell.loader import cell_from_mapping
from conveyor_twin.coord.assembly import build_twin

L_LINE = Path(__file__).resolve().parents[2] / 'conveyor_twin/cell/examples/l_line.yaml'
PARTS = 160
STEPS = 35000
STOP_STEPS = 8000
SAMPLE_STEPS = 100
# The bend's bounding box [m] (the curve of centre (2.0, 0.6), radii 0.4-0.8, -90..0 deg).
BEND_BOX = (2.0, -0.2, 2.8, 0.6)


def l_line_cell(policy: str):
    """Return the scenario's cell for zone ``policy`` (``micro`` or ``auto``)."""
    d = yaml.safe_load(L_LINE.read_text())
    d['sources'][0]['rate'] = 10.0
    d['sources'][0]['max_parts'] = PARTS
    d['zones'][0]['policy'] = policy
    return cell_from_mapping(d)


@functools.lru_cache(maxsize=None)
def l_line_run(policy: str, seed: int) -> Dict[str, object]:
    """Run the scenario; return ``queue`` and ``left`` [parts] every 0.1 s, the barrier edge
    ``counts``, the tile ``switches`` and the largest ledger residual."""
    built = build_twin(l_line_cell(policy), seed=seed)
    twin, micro, macro = built.twin, built.micro, built.macro
    coupling = twin.stages[-1]
    coupling.check = True
    twin.commands.submit_belt('outfeed', 0.0)
    queue, left = [], []
    x0, y0, x1, y1 = BEND_BOX
    for k in range(STEPS // SAMPLE_STEPS):
        if k * SAMPLE_STEPS == STOP_STEPS:
            twin.commands.submit_belt('outfeed', 0.5)
        twin.step(SAMPLE_STEPS)
        v = micro.sim.parts_view()
        q = float(((v.x >= x0) & (v.x < x1) & (v.y >= y0) & (v.y < y1)).sum())
        out = float(micro.sim.left[0])
        if coupling.enabled:
            q += macro.grids[0].region_parts(BEND_BOX)
            out += coupling.left_macro
        queue.append(q)
        left.append(out)
    return {'queue': np.array(queue), 'left': np.array(left),
            'counts': micro.barrier_edge_count().astype(int).tolist(),
            'switches': coupling.regions[0].tiles.switches if coupling.enabled else 0,
            'residual': coupling.max_residual if coupling.enabled else 0.0}


def mean_exit_time(left: np.ndarray) -> float:
    """Mean time [s] at which the parts leave: the integral of the parts not yet out."""
    return float((PARTS - left).sum()) * SAMPLE_STEPS * 1e-3 / PARTS


def exit_time(left: np.ndarray, fraction: float) -> float:
    """Time [s] at which ``fraction`` of the parts have left."""
    return (int(np.argmax(left >= fraction * PARTS)) + 1) * SAMPLE_STEPS * 1e-3
