"""Light barriers in sensor windows: which edges multi-scale reproduces exactly, which only
statistically (issue 6: "barrier edge counts in sensor windows identical in count").

Scenario of ``test_validation.py``: the default cell, 2400 parts at 500 parts/s, an ``auto``
zone over the whole belt, the jam in front of the deflector goes macro. Barriers: lb_infeed
(x = 2.0, upstream of the jam), lb_after_deflector (x = 3.6) and lb_exit (x = 5.7), both fed
by the jam's discharge through the deflector gap. Method and measurements:
docs/scale_validation.md. In short (commit c05a136, 16 pure micro and 15 multi-scale runs):

* lb_infeed sees the head of the flow (free ride on the belt, no contacts) and the tail of the
  queue. Its head edges (t < 5 s) are identical to the nanosecond at both scales in all 15
  multi-scale runs; sub-physical perturbations of pure micro (belt speed x (1 + 1e-12), spawn
  positions + 1e-9 m) leave its whole edge list unchanged (but for the 2 ns the spawn shift
  takes at 0.5 m/s). The tail is fed by the last parts of the feed, which in multi-scale went
  through the tiles near the source (x = 0.2..1.0, macro at 3..6 s in the 500 parts/s feed):
  its edges move by up to 70 ms (2 of 8 seeds) and the count is identical in 14 of 15 runs,
  10 vs 8 in one (seed 1, belt speed x (1 + 1e-12)). Exact claim: the head edges; the count
  within one gap (2 edges).
* lb_after_deflector / lb_exit: the beam is blocked through the whole dense discharge (~5 s);
  the count is 2 x (1 + gaps wider than the beam), the gaps being the few parts trickling
  through the gap before the jam closes it and the last ones after it dissolves. In pure micro
  these are chaotic: the same perturbations change lb_after_deflector from 18 to 16 and 20
  edges (seed 1), and over 16 runs (8 seeds, 8 perturbed) it spans 16..36 (mean 21.3, std
  5.3). Pure micro does not reproduce its own counts; "identical" cannot hold there. The
  multi-scale counts (14..28 and 12..24, 15 runs) are compared statistically.
* Pure micro moves the parts from x = 3.6 to 5.7 on the belt without contacts: lb_exit sees
  lb_after_deflector's edges exactly 4.2 s later (16 of 16 runs). Multi-scale breaks this
  (tiles at x = 3.8..4.2 and 4.8..5.6 go macro in the dense discharge, the parts are captured
  and re-released): 3 of 4 seeds here differ.

Cost: 6 pure micro runs (~6 s each) and 4 multi-scale runs (~11 s each): 87..92 s measured.
"""

from typing import Dict, List, Tuple

import numpy as np
import pytest
import yaml

from conveyor_twin.cell.loader import cell_from_mapping, default_cell_text
from conveyor_twin.coord.stages import MacroStage, MicroStage
from conveyor_twin.coord.twin import Twin

pytestmark = pytest.mark.slow

SEEDS = (1, 2, 3, 4)
STEPS = 20000
SAMPLE_STEPS = 100
PARTS = 2400
INFEED, AFTER_DEFLECTOR, EXIT = 0, 1, 2
# The head of the flow passes lb_infeed at 3.5..3.7 s; the queue's tail reaches it after 8 s.
HEAD_END_NS = 5_000_000_000
# lb_after_deflector -> lb_exit: 2.1 m at the belt speed of 0.5 m/s
TRANSIT_NS = 4_200_000_000
# Sub-physical perturbations of pure micro (seed 1): the belt speed in the 12th digit; every
# spawn position moved 1e-9 m along the belt.
PERTURBATIONS = ('belt_speed_1e-12', 'spawn_shift_1e-9m')


def _cell(policy: str, perturbation: str = ''):
    d = yaml.safe_load(default_cell_text())
    d['sources'][0]['rate'] = 500.0
    d['sources'][0]['max_parts'] = PARTS
    d['macro']['epsilon'] = 0.8
    d['zones'] = [{'name': 'belt', 'policy': policy, 'region': [0.0, -0.25, 6.0, 0.25],
                   'resolution': 0.02,
                   'auto': {'tile': 0.2, 'to_macro_density': 3000.0,
                            'to_micro_density': 1000.0, 'min_dwell': 0.2,
                            'sensor_margin': 0.05}}]
    if perturbation == 'belt_speed_1e-12':
        d['belts'][0]['speed'] = 0.5 * (1.0 + 1e-12)
    elif perturbation == 'spawn_shift_1e-9m':
        r = d['sources'][0]['region']
        d['sources'][0]['region'] = [r[0] + 1e-9, r[1], r[2] + 1e-9, r[3]]
    else:
        assert perturbation == ''
    return cell_from_mapping(d)


def _run(policy: str, seed: int, perturbation: str = '') -> Dict[str, object]:
    """Run the deflector jam; return every barrier edge (barrier, blocked, time [ns]), the edge
    counts and the parts out through the exit every 0.1 s."""
    cell = _cell(policy, perturbation)
    micro, macro = MicroStage(cell, seed), MacroStage(cell)
    twin = Twin(cell, seed=seed, stages=[micro, macro])
    coupling = twin.stages[-1]
    edges: List[Tuple[int, bool, int]] = []
    left: List[float] = []
    for k in range(STEPS):
        twin.step(1)
        b, blocked, t, _ = micro.edges()
        edges.extend(zip(b.tolist(), blocked.tolist(), t.tolist()))
        if (k + 1) % SAMPLE_STEPS == 0:
            left.append(float(micro.sim.left[0])
                        + (coupling.left_macro if coupling.enabled else 0.0))
    if policy == 'auto':
        assert coupling.regions[0].tiles.switches > 0
    return {'edges': edges, 'counts': micro.barrier_edge_count().astype(int).tolist(),
            'left': np.array(left)}


def _barrier(run, index: int) -> List[Tuple[bool, int]]:
    return [(blocked, t) for b, blocked, t in run['edges'] if b == index]


@pytest.fixture(scope='module')
def runs() -> Dict[Tuple[str, int, str], Dict[str, object]]:
    out = {}
    for seed in SEEDS:
        out[('micro', seed, '')] = _run('micro', seed)
        out[('auto', seed, '')] = _run('auto', seed)
    for p in PERTURBATIONS:
        out[('micro', 1, p)] = _run('micro', 1, p)
    return out


def test_upstream_window_is_exact(runs) -> None:
    """lb_infeed: the head of the flow (parts that never met the macro scale) identical to the
    nanosecond; the count within one gap (its tail went through the macro tiles at the source)."""
    for seed in SEEDS:
        micro, multi = runs[('micro', seed, '')], runs[('auto', seed, '')]
        assert micro['counts'][INFEED] > 0
        assert abs(multi['counts'][INFEED] - micro['counts'][INFEED]) <= 2
        head = [e for e in _barrier(micro, INFEED) if e[1] < HEAD_END_NS]
        assert len(head) >= 3
        assert [e for e in _barrier(multi, INFEED) if e[1] < HEAD_END_NS] == head


def test_sub_physical_perturbations_keep_the_upstream_window_and_scramble_the_downstream_one(
        runs) -> None:
    """The premise of the statistical claim: pure micro reproduces lb_infeed under a 1e-12 /
    1e-9 m perturbation, but not the edges behind the jam."""
    ref = runs[('micro', 1, '')]
    for p in PERTURBATIONS:
        run = runs[('micro', 1, p)]
        a, b = _barrier(run, INFEED), _barrier(ref, INFEED)
        assert [k for k, _ in a] == [k for k, _ in b]
        assert max(abs(ta - tb) for (_, ta), (_, tb) in zip(a, b)) <= 10  # ns
        assert run['counts'][AFTER_DEFLECTOR] != ref['counts'][AFTER_DEFLECTOR]


def test_pure_micro_carries_the_downstream_pattern_to_the_exit_unchanged(runs) -> None:
    """Between x = 3.6 and 5.7 the parts ride the belt without contacts: lb_exit sees
    lb_after_deflector's edges 4.2 s later (within a step)."""
    for key, run in runs.items():
        if key[0] != 'micro':
            continue
        after, out = _barrier(run, AFTER_DEFLECTOR), _barrier(run, EXIT)
        assert len(after) == len(out) > 0
        for (ka, ta), (ke, te) in zip(after, out):
            assert ka == ke and abs(te - ta - TRANSIT_NS) <= 1_000_000


@pytest.mark.parametrize('barrier', [AFTER_DEFLECTOR, EXIT])
def test_downstream_counts_agree_with_pure_micro_statistically(runs, barrier) -> None:
    """Multi-scale counts behind the jam against the pure micro ensemble (seeds and
    sub-physical perturbations): the means within 3 standard errors, every run within [1/2, 2]
    of pure micro's range (a lock-step release or a flickering beam falls out of it)."""
    micro = np.array([r['counts'][barrier] for k, r in runs.items() if k[0] == 'micro'], float)
    multi = np.array([r['counts'][barrier] for k, r in runs.items() if k[0] == 'auto'], float)
    se = np.sqrt(micro.var(ddof=1) / len(micro) + multi.var(ddof=1) / len(multi))
    assert abs(multi.mean() - micro.mean()) <= 3.0 * max(se, 1.0)
    assert multi.min() >= 0.5 * micro.min() and multi.max() <= 2.0 * micro.max()


def _plateau_rate(left: np.ndarray) -> float:
    """Exit rate [parts/s] while the 10 % .. 90 % of the parts leave."""
    k10, k90 = int(np.argmax(left >= 0.1 * PARTS)), int(np.argmax(left >= 0.9 * PARTS))
    return 0.8 * PARTS / ((k90 - k10) * SAMPLE_STEPS * 1e-3)


@pytest.mark.xfail(strict=True, reason='the macro jam discharges ~15 % slower and longer '
                   '(plateau 384..409 vs 446..492 parts/s, 15 vs 16 runs, outside pure micro '
                   'spread); the mean exit time agrees (test_validation). docs/scale_validation.md')
def test_exit_plateau_rate_within_pure_micro_spread(runs) -> None:
    micro = [_plateau_rate(r['left']) for k, r in runs.items() if k[0] == 'micro']
    multi = [_plateau_rate(r['left']) for k, r in runs.items() if k[0] == 'auto']
    assert min(micro) * 0.95 <= min(multi) and max(multi) <= max(micro) * 1.05
