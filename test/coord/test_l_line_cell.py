"""The L-shaped line end to end against a lockstep twin: straight, curve, straight, sink.

Every part is followed through the ``parts`` stream by its id. On a belt that it sticks to, a
part's travel time between two cross-sections of the line is the centre-line length between
them divided by the belt speed, whatever its lateral position: on the straights every point
moves at the belt speed, and the curve turns rigidly about its centre (omega = speed /
centre_radius), so any radius takes sweep / omega = centre-line length / speed.
"""

import math
from pathlib import Path
from typing import Dict, List

import numpy as np
import pytest

from conveyor_twin.wire.cdr import decode_part_states

pytestmark = [pytest.mark.ros, pytest.mark.slow]
CELL = Path(__file__).resolve().parents[2] / 'conveyor_twin' / 'cell' / 'examples' / 'l_line.yaml'
CHUNK = 20
DT = 0.001                   # s, the cell's step
SPEED = 0.5                  # m/s, every belt (centre line of the curve)
CENTRE = (2.0, 0.6)          # m, the curve's centre; its centre radius 0.6 m, a quarter turn
RADIUS = 0.6
CURVE = RADIUS * math.pi / 2  # m, centre-line length of the curve
BEFORE_X = 1.8               # m, lb_before's beam (across the infeed)
AFTER_Y = 0.8                # m, lb_after's beam (across the outfeed)
SINK_Y = 2.55                # m, the sink's lower edge: a part whose centre is past it leaves
PARTS = 8                    # parts that leave before the run ends
# longest wait for one answer of the twin [s]: the first step of a run may compile the
# simulation kernels, minutes on a loaded machine
TIMEOUT = 300.0
# Bound on the difference from centre-line length / speed [s]. Where a part passes from a
# straight onto the curve off the centre line, the surface under it changes speed by up to
# |r - 0.6 m| * omega <= 0.15 * 0.5 / 0.6 = 0.125 m/s (cans reach 0.15 m either side); it slips
# until it matches, at up to mu_belt * g = 3.4 m/s^2: it falls back (or ahead) by
# dv^2 / (2 a) = 2.3 mm (4.6 ms), and gains (loses) about as much at the joint to the outfeed.
# We allow 20 ms (10 mm of travel): one joint's slip even at a third of that deceleration
# (6.9 mm, 14 ms), plus one step (1 ms) for the sampling of the exit. Seed 1 stays within 1.2 ms.
TOLERANCE = 0.02


def progress(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distance along the centre line [m] of the points' nearest centre-line position: x on
    the infeed, the arc on the curve, 2.0 + the curve + (y - 0.6) on the outfeed."""
    angle = np.arctan2(y - CENTRE[1], x - CENTRE[0]) + math.pi / 2  # 0 .. pi/2 on the curve
    on_curve = (x > CENTRE[0]) & (y < CENTRE[1])
    return np.where(x <= CENTRE[0], x,
                    np.where(on_curve, CENTRE[0] + RADIUS * angle,
                             CENTRE[0] + CURVE + (y - CENTRE[1])))


def tracks(twin) -> Dict[int, List[tuple]]:
    """Every part's samples (step, x, y) from the ``parts`` stream, by id."""
    out: Dict[int, List[tuple]] = {}
    for data in twin.messages('parts'):
        msg = decode_part_states(data)
        for i, x, y in zip(msg.id.tolist(), msg.x.tolist(), msg.y.tolist()):
            out.setdefault(i, []).append((msg.step, x, y))
    return out


def crossing(track: np.ndarray, s: np.ndarray, at: float) -> float:
    """Time [s] the part's progress first reached ``at``, interpolated between steps."""
    k = int(np.argmax(s >= at))
    assert s[k] >= at and k > 0
    frac = (at - s[k - 1]) / (s[k] - s[k - 1])
    return (track[k - 1, 0] + frac) * DT


def test_parts_travel_the_l_and_leave_in_centre_line_time(conveyor_twin_factory):
    twin = conveyor_twin_factory(CELL, seed=1, chunk=CHUNK, timeout=TIMEOUT)
    coupling = twin.composed.assembled.coupling
    twin.step_until(lambda: coupling.ledger()['left'] >= PARTS, max_steps=30_000,
                    what=f'{PARTS} parts left through the sink')
    last_step = twin.step_index
    ledger = coupling.ledger()
    # every part accounted for; the line stayed sparse: all of them micro
    assert ledger['residual'] == 0.0 and ledger['vanished'] == 0.0
    assert ledger['macro'] == 0.0 and ledger['pending'] == 0.0
    assert ledger['entered'] == ledger['micro'] + ledger['left']
    followed = tracks(twin)
    assert len(followed) == ledger['entered']
    gone = {i: np.array(t) for i, t in followed.items() if t[-1][0] < last_step}
    assert len(gone) == ledger['left'] >= PARTS
    # barriers in order: a part's lb_after edge follows its lb_before edge by the centre-line
    # time between the beams (both edges at the can's rim: the same offset before each beam)
    before = {e.part_id: e.time_ns for e in twin.edges(name='lb_before') if e.blocked}
    after = {e.part_id: e.time_ns for e in twin.edges(name='lb_after') if e.blocked}
    between = ((CENTRE[0] - BEFORE_X) + CURVE + (AFTER_Y - CENTRE[1])) / SPEED
    assert len(set(after) & set(gone)) >= PARTS // 2
    for part, t in after.items():
        assert part in before, f'part {part} passed lb_after without passing lb_before'
        assert (t - before[part]) * 1e-9 == pytest.approx(between, abs=TOLERANCE), part
    # centre line from lb_before's beam to the sink's edge: the rest of the infeed, the curve,
    # the outfeed up to y = 2.55
    path = (CENTRE[0] - BEFORE_X) + CURVE + (SINK_Y - CENTRE[1])
    for part, track in gone.items():
        s = progress(track[:, 1], track[:, 2])
        x0, y0 = track[0, 1:]
        assert 0.05 <= x0 <= 0.25 and -0.15 <= y0 <= 0.15, part  # from the source, on the infeed
        assert np.all(np.diff(s) >= -1e-3), part                 # always onward along the L
        assert np.any((track[:, 1] > CENTRE[0]) & (track[:, 2] < CENTRE[1])), part  # the curve
        x1, y1 = track[-1, 1:]
        assert 2.3 <= x1 <= 2.9 and SINK_Y - SPEED * DT * 1.5 <= y1 < SINK_Y, part
        at_before = crossing(track, s, BEFORE_X)
        left_at = (track[-1, 0] + 1) * DT                        # the step it was gone
        assert left_at - at_before == pytest.approx(path / SPEED,
                                                             abs=TOLERANCE), part
