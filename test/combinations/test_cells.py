"""Every cell x every output of a composed run, one fault of each family armed.

One lockstep run per cell (module scope) is watched through ROS by the testing harness and
through a Foxglove client at once; ``conveyor-twin run --record`` records the same cell, seed,
belt command and faults. Each output must be live (a message for every step of every stream the
cell produces, except while a ``stream_outage`` silences it) and agree with the others for the
same step, the recording must re-simulate bit for bit, and ``plot`` and ``animate`` must draw
it without a warning. The shipped cells run by default; the example plant's cells, run on their
own, are in the long part (``-m matrix_long``).
"""

import pytest

from conveyor_twin.record.resimulate import resimulate
from conveyor_twin.wire import cdr

from . import checks, matrix
from .runs import cli, forwarded_steps, lockstep_run, record, recorded

pytestmark = [pytest.mark.ros, pytest.mark.slow]
pytest.importorskip('websockets.sync.client')
pytest.importorskip('foxglove')

CASES = [pytest.param(case, id=case.key) for case in matrix.SHIPPED_CELLS] + [
    pytest.param(case, id=case.key, marks=pytest.mark.matrix_long)
    for case in matrix.PLANT_CELLS]
#: Streams of a recording checked for a message at every step.
RECORDED_PER_STEP = matrix.PER_STEP


@pytest.fixture(scope='module', params=CASES)
def case(request):
    return request.param


@pytest.fixture(scope='module')
def scenario(case, tmp_path_factory):
    return matrix.write_scenario(tmp_path_factory.mktemp(case.key) / 'faults.yaml', case)


@pytest.fixture(scope='module')
def run(case, scenario):
    return lockstep_run(case, scenario)


@pytest.fixture(scope='module')
def recording(case, scenario):
    path = scenario.parent / 'run.mcap'
    record(case, scenario, path)
    return path


def test_every_fault_family_takes_effect(run):
    """The faults stream states each fault active from its step, and its end."""
    from conveyor_twin.wire.decoders import decode_fault_state
    states = [decode_fault_state(d) for d in run.ros['faults']]
    seen = {f.kind: s.stamp_ns // run.step_ns for s in reversed(states) for f in s.active}
    wanted = {e['kind']: e['at']['step'] for e in matrix.fault_entries(run.case)}
    assert seen == wanted
    assert states[-1].active == () and states[-1].total_injected == len(wanted)


def test_the_faults_show_in_the_streams(run):
    """The belt stalls (actual speed 0 while stalled, ramping up after), the belt command takes
    effect after the commands' delay, the chattering barrier reports an edge every half period
    (where its edges are not silenced)."""
    from conveyor_twin.wire.decoders import decode_belt_states, decode_light_barrier_edge
    faults = {e['kind']: e for e in matrix.fault_entries(run.case)}
    belts = {cdr.stamp_of(d) // run.step_ns: decode_belt_states(d)
             for d in run.ros['belt_states']}
    stall = faults['belt_stall']
    first = stall['at']['step']
    end = first + round(stall['duration'] * 1e9 / run.step_ns)
    assert [k for k in range(first, end) if k in belts and belts[k].actual[0] != 0.0] == []
    assert belts[first - 1].actual[0] > 0.0 and belts[end].actual[0] > 0.0
    _, speed = matrix.belt_command(run.case)
    effect = matrix.COMMAND_STEP + round(faults['command_delay']['params']['delay'] * 1e9
                                         / run.step_ns)
    assert belts[effect - 1].commanded[0] != speed and belts[effect].commanded[0] == speed
    chatter = faults['barrier_chatter']
    half = round(0.5e9 / chatter['params']['frequency'])
    start = chatter['at']['step'] * run.step_ns
    stop = start + round(chatter['duration'] * 1e9)
    silenced = run.silenced().get('/light_barrier_edges', set())
    edges = [e.stamp_ns for e in map(decode_light_barrier_edge, run.ros['light_barrier_edges'])
             if e.name == chatter['target'] and start <= e.stamp_ns < stop]
    assert edges == [t for t in range(start, stop, half) if t // run.step_ns not in silenced]


def test_ros_streams_are_live(run):
    checks.ros_is_live(run)
    assert len(run.ros['command_status']) == 1, 'one answer to the one belt command'


def test_foxglove_is_live_and_agrees_with_ros(run):
    """The client gets every frame the view forwards (the first step after it subscribed, then
    one in ``every``) with every per-step stream the cell produces, as ROS had it; every edge
    and fault state; a scene and each macro zone's density grid, equal to the ROS density."""
    checks.foxglove_agrees(run)
    silenced = run.silenced()
    for name in checks.STEP_STREAMS:
        topic = '/' + name
        if checks.per_step(run, name):
            got = sorted({m.log_time for m in run.foxglove if m.topic == topic})
            assert got == [k * run.step_ns for k in forwarded_steps(run)
                           if k not in silenced.get(topic, ())], f'Foxglove {topic}'


def test_recording_is_live(run, recording):
    messages = recorded(recording)
    silenced = run.silenced()
    for topic in RECORDED_PER_STEP + ('/density',):
        per_step = checks.per_step(run, topic)
        if not per_step:
            assert topic not in messages
            continue
        gaps = matrix.step_gaps(messages.get(topic, []), run.step_ns, run.steps,
                                silenced.get(topic, set()), per_step)
        assert gaps is None, f'recorded {topic} of {run.case.key}: {gaps}'


def test_recording_agrees_with_ros(run, recording):
    """The recorded streams are the bytes the harness received (same cell, seed, command and
    faults, composed in fast mode against lockstep): barriers, edges, parts, density, states,
    fault states; /clock where ROS delivered it."""
    messages = recorded(recording)
    for name in ('parts', 'density', 'light_barriers', 'light_barrier_edges', 'belt_states',
                 'actuator_states', 'faults'):
        got = messages.get('/' + name, [])
        assert got == run.ros[name], (f'/{name}: recorded {len(got)} messages, ROS '
                                      f'{len(run.ros[name])}, first difference at '
                                      f'{_first_difference(got, run.ros[name])}')
    clock = set(messages['/clock'])
    assert set(run.ros['/clock']) <= clock


def _first_difference(a, b) -> int:
    return next((i for i, (x, y) in enumerate(zip(a, b)) if x != y), min(len(a), len(b)))


def test_recording_resimulates_bit_for_bit(run, recording):
    report = resimulate(str(recording))
    assert report.ok, str(report.difference)
    assert report.faults == len(matrix.families_of(run.case)) and report.commands == 1
    for topic in ('/parts', '/light_barriers', '/belt_states', '/clock', '/faults'):
        assert report.compared[topic] > 0, topic


def _no_warnings(done, what: str) -> None:
    assert done.returncode == 0, f'{what}: exit {done.returncode}\n{done.stderr}'
    assert 'warning' not in (done.stderr + done.stdout).lower(), f'{what}:\n{done.stderr}'


def test_plot_draws_the_cell(case, tmp_path):
    out = tmp_path / 'cell.png'
    _no_warnings(cli(['plot', str(case.path), '-o', str(out)]), f'plot {case.path}')
    assert out.stat().st_size > 0


def test_plot_draws_the_recording(run, recording, tmp_path):
    done = cli(['plot', str(recording), '-o', str(tmp_path)])
    _no_warnings(done, f'plot {recording}')
    cell = run.case.cell
    wanted = {'light_barriers.png', 'belt_speeds.png'}
    if cell.actuators:
        wanted.add('actuators.png')
    if matrix.macro_zones(cell):
        wanted.add('density.png')
    if any(cdr.decode_part_states(d).id.size for d in run.ros['parts']):
        wanted |= {'trajectories_xy.png', 'trajectories_x.png'}
    written = {p.name for p in tmp_path.glob('*.png')}
    assert wanted <= written, f'missing {sorted(wanted - written)}'
    assert written <= wanted | {'actuators.png'}, f'unexpected {sorted(written - wanted)}'
    assert all(p.stat().st_size > 0 for p in tmp_path.glob('*.png'))


def test_animate_renders_the_recording(recording, tmp_path):
    out = tmp_path / 'run.gif'
    _no_warnings(cli(['animate', str(recording), '-o', str(out), '--quiet']),
                 f'animate {recording}')
    assert out.stat().st_size > 0
