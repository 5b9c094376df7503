"""Checks of one run's outputs against each other, shared by the composed and split tests."""

import numpy as np

from conveyor_twin.wire import cdr

from . import matrix
from .foxglove_client import decode_grid
from .runs import CellRun

#: Per-step streams by contract name.
STEP_STREAMS = ('parts', 'density', 'light_barriers', 'belt_states', 'actuator_states')


def per_step(run: CellRun, name: str) -> int:
    """Messages of stream ``name`` per step for the run's cell."""
    return len(matrix.macro_zones(run.case.cell)) if name.strip('/') == 'density' else 1


def ros_is_live(run: CellRun) -> None:
    """Every per-step stream has its messages at every step except while silenced; /clock (best
    effort, keep-last 1) arrives in order and for the last step."""
    silenced = run.silenced()
    assert silenced, 'the stream_outage silenced nothing'
    for name in STEP_STREAMS:
        if not per_step(run, name):
            assert run.ros[name] == [], f'{name}: messages from a cell without macro zones'
            continue
        gaps = matrix.step_gaps(run.ros[name], run.step_ns, run.steps,
                                silenced.get('/' + name, set()), per_step(run, name))
        assert gaps is None, f'ROS {name} of {run.case.key}: {gaps}'
    clock = [cdr.decode_clock(d) for d in run.ros['/clock']]
    assert clock == sorted(set(clock)) and clock[-1] == run.steps * run.step_ns


def foxglove_agrees(run: CellRun) -> None:
    """What the Foxglove client got is what ROS carried, and it is live.

    Every per-step message has the bytes ROS had for its step; each stream the cell produces
    comes at least once in every ``every`` steps (a stream_outage's span and a slot more aside)
    from when the client watched to the end; every edge and fault state since then is
    forwarded; the scene comes, and each macro zone's density grid is the ROS density of its
    step.
    """
    assert not run.foxglove_error, run.foxglove_error
    assert not [s for s in run.foxglove_statuses if s.get('level', 0) >= 2], \
        run.foxglove_statuses
    silenced = run.silenced()
    since = run.foxglove_from * run.step_ns
    for name in STEP_STREAMS + ('/clock',):
        topic = '/' + name.lstrip('/')
        if not per_step(run, name):
            continue
        got = matrix.by_stamp(m.data for m in run.foxglove if m.topic == topic)
        ros = matrix.by_stamp(run.ros[name])
        for stamp, data in got.items():
            assert stamp % run.step_ns == 0 and 0 < stamp // run.step_ns <= run.steps
            assert stamp // run.step_ns not in silenced.get(topic, ()), \
                f'Foxglove {topic} at {stamp} ns, while silenced'
            if name != '/clock' or stamp in ros:  # ROS has every step but of /clock
                assert data == ros.get(stamp), f'Foxglove {topic} at {stamp} ns differs from ROS'
        steps = [run.foxglove_from] + sorted(s // run.step_ns for s in got) + [run.steps + 1]
        for a, b in zip(steps, steps[1:]):
            # the view forwards one message in ``every`` (of the frames, or of the stream's
            # messages): a silenced span may cost one more slot on top of its own length
            quiet = len([k for k in range(a + 1, b) if k in silenced.get(topic, ())])
            assert b - a <= quiet + (2 if quiet else 1) * run.foxglove_every, \
                f'Foxglove {topic}: nothing between steps {a} and {b}'
    for name in ('light_barrier_edges', 'faults'):
        got = [m.data for m in run.foxglove if m.topic == '/' + name]
        ros = run.ros[name]
        since_then = [d for d in ros if cdr.stamp_of(d) > since]
        assert len(got) >= len(since_then) and got == ros[len(ros) - len(got):], (
            f'Foxglove /{name}: {len(got)} messages, ROS {len(ros)} ({len(since_then)} since '
            f'the client watches); they differ')
    assert [m for m in run.foxglove if m.topic == '/scene'], 'no scene'
    density = matrix.by_stamp(run.ros['density'])
    for zone in matrix.macro_zones(run.case.cell):
        frames = [m for m in run.foxglove if m.topic == f'/scene/density/{zone}']
        assert frames, f'no density grid of zone {zone!r} on Foxglove'
        for frame in frames:
            grid = decode_grid(frame.data)
            assert grid.stamp_ns == frame.log_time
            ros = [g for g in map(cdr.decode_density_grid, density.get(grid.stamp_ns, []))
                   if g.zone == zone]
            assert len(ros) == 1, f'ROS density of {zone!r} at {grid.stamp_ns} ns'
            assert grid.field_names == ('density',)
            assert grid.values.shape == ros[0].density.shape
            np.testing.assert_array_equal(grid.values, ros[0].density.astype('<f4'))
            assert (grid.origin, grid.resolution) == (
                (ros[0].origin_x, ros[0].origin_y), ros[0].resolution)
