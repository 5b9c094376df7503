"""The split layout x every cell x every fault family, against the composed layout (long).

Each fault family on its own: the split twin (micro, macro and coordinator as three processes)
and the composed one, both in lockstep with the same cell, seed, belt command and fault, must
give the same bytes on every stream the harness reads, and the split run's streams must be
live. One split run per cell with every family and a Foxglove client checks the view the
coordinator process serves against ROS.
"""

import pytest

from . import checks, matrix
from .runs import lockstep_run

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.matrix_long]

COMBINATIONS = [pytest.param(case, family, id=f'{case.key}-{family}')
                for case in matrix.CELLS for family in matrix.families_of(case)]
#: Streams compared message for message (``/clock`` is best effort: compared by stamp).
COMPARED = ('parts', 'density', 'light_barriers', 'light_barrier_edges', 'belt_states',
            'actuator_states', 'faults')


@pytest.mark.parametrize('case, family', COMBINATIONS)
def test_split_agrees_with_composed(case, family, tmp_path):
    scenario = matrix.write_scenario(tmp_path / 'fault.yaml', case, [family])
    split = lockstep_run(case, scenario, layout='split', foxglove=False)
    composed = lockstep_run(case, scenario, foxglove=False)
    for name in COMPARED:
        assert split.ros[name] == composed.ros[name], \
            f'{case.key}, {family}: {name} of the split layout differs from the composed one'
    clock_split = matrix.by_stamp(split.ros['/clock'])
    clock_composed = matrix.by_stamp(composed.ros['/clock'])
    assert all(clock_split[t] == clock_composed[t] for t in set(clock_split) & set(clock_composed))
    for name in checks.STEP_STREAMS:
        if not checks.per_step(split, name):
            continue
        gaps = matrix.step_gaps(split.ros[name], split.step_ns, split.steps,
                                split.silenced().get('/' + name, set()),
                                checks.per_step(split, name))
        assert gaps is None, f'split {name}: {gaps}'


@pytest.mark.parametrize('case', [pytest.param(c, id=c.key) for c in matrix.CELLS])
def test_split_foxglove_is_live_and_agrees_with_ros(case, tmp_path):
    scenario = matrix.write_scenario(tmp_path / 'faults.yaml', case)
    run = lockstep_run(case, scenario, layout='split')
    checks.ros_is_live(run)
    checks.foxglove_agrees(run)
