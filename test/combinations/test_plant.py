"""The example plant's cells as plant cells x every output (long).

``conveyor-twin plant examples/plant/plant.yaml`` records every cell (``--record DIR``) in one
process and in one process per cell: each cell's recording is live (a message of every
per-step stream at every step, under the cell's namespace) and the two layouts give the same
bytes. ``plot`` and ``animate`` draw every cell's recording and ``plot`` the plant file, without
a warning. In realtime, the cells take one fault of each family over ROS, and ``--foxglove``
serves every cell in one view: the client gets each cell's streams and scene, with the bytes
the cell recorded for the same step.
"""

from pathlib import Path
import signal
import subprocess
import sys

import pytest

from conveyor_twin.plant.loader import load_plant
from conveyor_twin.testing import ros_subprocess_env
from conveyor_twin.wire import cdr
from conveyor_twin.wire.decoders import decode_fault_state

from . import matrix
from .foxglove_client import FoxgloveClient
from .runs import cli, CLI_TIMEOUT, free_port, recorded

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.matrix_long]

#: Simulated time of the fast runs: parts pass every link of the example plant [s].
DURATION = 20.0
PLANT = load_plant(str(matrix.PLANT))
CELLS = [pytest.param(c.name, id=c.name) for c in PLANT.cells]
PER_STEP = ('parts', 'light_barriers', 'belt_states', 'actuator_states')


def _plant(args, **kwargs) -> subprocess.CompletedProcess:
    done = cli(['plant', str(matrix.PLANT), '--quiet', '--json', *args], **kwargs)
    assert done.returncode == 0, f'plant {" ".join(args)}: exit {done.returncode}\n' \
                                 f'{done.stderr[-3000:]}'
    return done


@pytest.fixture(scope='module')
def composed(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp('plant_composed')
    _plant(['--composed', '--mode', 'fast', '--duration', str(DURATION), '--record', str(out)])
    return out


@pytest.fixture(scope='module')
def processes(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp('plant_processes')
    _plant(['--processes', '--mode', 'fast', '--duration', str(DURATION), '--record',
            str(out)])
    return out


def _namespace(cell: str) -> str:
    return '/' + next(c.namespace for c in PLANT.cells if c.name == cell).strip('/')


@pytest.mark.parametrize('cell', CELLS)
def test_every_plant_cell_recording_is_live(composed, cell):
    messages = recorded(composed / f'{cell}.mcap')
    ns = _namespace(cell)
    step = PLANT.cells[0].cell.settings.step
    steps, step_ns = round(DURATION / step), round(step * 1e9)
    for name in PER_STEP:
        gaps = matrix.step_gaps(messages.get(f'{ns}/{name}', []), step_ns, steps, set())
        assert gaps is None, f'{cell}: {ns}/{name}: {gaps}'
    assert matrix.step_gaps(messages.get('/clock', []), step_ns, steps, set()) is None


def test_the_parts_pass_every_link(composed):
    for cell in PLANT.cells:
        parts = recorded(composed / f'{cell.name}.mcap')[f'{_namespace(cell.name)}/parts']
        assert any(cdr.decode_part_states(d).id.size for d in parts), \
            f'{cell.name}: no part in {DURATION:g} s'


@pytest.mark.parametrize('cell', CELLS)
def test_one_process_per_cell_records_the_bytes_of_one_process(composed, processes, cell):
    a, b = recorded(composed / f'{cell}.mcap'), recorded(processes / f'{cell}.mcap')
    ns = _namespace(cell)
    for name in PER_STEP + ('light_barrier_edges', 'faults'):
        topic = f'{ns}/{name}'
        assert a.get(topic) == b.get(topic), f'{cell}: {topic} differs between the layouts'


@pytest.mark.parametrize('cell', CELLS)
def test_plot_and_animate_every_plant_cell(composed, cell, tmp_path):
    path = composed / f'{cell}.mcap'
    done = cli(['plot', str(path), '-o', str(tmp_path / 'figures')])
    assert done.returncode == 0 and 'warning' not in done.stderr.lower(), done.stderr
    assert {'light_barriers.png', 'belt_speeds.png'} <= {
        p.name for p in (tmp_path / 'figures').glob('*.png')}
    gif = tmp_path / 'run.gif'
    done = cli(['animate', str(path), '-o', str(gif), '--quiet', '--start', str(DURATION - 6),
                '--speed', '6'])
    assert done.returncode == 0 and 'warning' not in done.stderr.lower(), done.stderr
    assert gif.stat().st_size > 0


def test_plot_draws_the_plant(tmp_path):
    out = tmp_path / 'plant.png'
    done = cli(['plot', str(matrix.PLANT), '-o', str(out)])
    assert done.returncode == 0, done.stderr
    assert 'warning' not in (done.stderr + done.stdout).lower(), done.stderr
    assert out.stat().st_size > 0


#: One fault of each family, injected over ROS into the running plant: (cell, kind, target,
#: parameters). Each lasts :data:`FAULT_DURATION`.
PLANT_FAULTS = (
    ('deflector', 'barrier_chatter', 'lb_exit', {'frequency': 20.0}),
    ('infeed', 'belt_stall', 'main', {}),
    ('deflector', 'actuator_offset', 'pusher', {'offset': 0.005}),
    ('sorter', 'command_drop', 'belt_command', {}),
    ('deflector', 'parts_vanish', '', {'x0': 1.0, 'y0': -0.25, 'x1': 2.0, 'y1': 0.25}),
    ('sorter', 'stream_outage', 'light_barriers', {}),
)
FAULT_DURATION = 0.5  # s


class _FaultInjector:
    """Inject faults into the plant's cells through their ``inject_fault`` services and follow
    each cell's ``faults`` stream."""

    def __init__(self, context) -> None:
        from conveyor_twin_msgs.srv import InjectFault
        from rclpy.node import Node

        from conveyor_twin.ros.compat import make_executor
        self.InjectFault = InjectFault
        self.node = Node('matrix_fault_injector', context=context)
        self.executor = make_executor(context)
        self.executor.add_node(self.node)
        self.states = {c.name: [] for c in PLANT.cells}
        self._subscriptions = []
        from conveyor_twin_msgs.msg import FaultState

        from conveyor_twin.ros.qos import LATCHED_QOS
        for c in PLANT.cells:
            self._subscriptions.append(self.node.create_subscription(
                FaultState, f'{_namespace(c.name)}/faults',
                lambda data, name=c.name: self.states[name].append(data), LATCHED_QOS,
                raw=True))

    def inject(self, cell: str, kind: str, target: str, params: dict) -> None:
        from conveyor_twin.testing import wait_for
        client = self.node.create_client(self.InjectFault, f'{_namespace(cell)}/inject_fault')
        assert wait_for(client.service_is_ready, CLI_TIMEOUT, self.executor), \
            f'{cell}: no inject_fault service'
        future = client.call_async(self.InjectFault.Request(
            kind=kind, target=target, param_names=list(params),
            param_values=[float(v) for v in params.values()], duration=FAULT_DURATION))
        assert wait_for(future.done, CLI_TIMEOUT, self.executor), f'{cell}: inject_fault'
        assert future.result().success, future.result().message

    def all_expired(self, counts: dict) -> bool:
        """True once each cell's latest fault state counts its injected faults, none active."""
        from conveyor_twin.wire.decoders import decode_fault_state
        for cell, count in counts.items():
            if not self.states[cell]:
                return False
            latest = decode_fault_state(self.states[cell][-1])
            if latest.total_injected < count or latest.active:
                return False
        return True

    def close(self) -> None:
        self.executor.remove_node(self.node)
        self.node.destroy_node()


@pytest.mark.parametrize('layout', ['--composed', '--processes'])
def test_plant_in_realtime_with_faults_foxglove_and_recordings(layout, tmp_path, ros_context):
    """A realtime plant serving ``--foxglove`` and recording every cell takes one fault of each
    family over ROS. The client gets every cell's per-step streams and scene, each message
    what the cell recorded for that step (the view may skip steps); each recording states its
    faults and is live, but for the silenced stream while its outage lasted."""
    from conveyor_twin.testing import wait_for
    port = free_port()
    args = [sys.executable, '-m', 'conveyor_twin.cli', 'plant', str(matrix.PLANT), layout,
            '--mode', 'realtime', '--duration', '0', '--quiet', '--json',
            '--record', str(tmp_path), '--foxglove', f'127.0.0.1:{port}']
    process = subprocess.Popen(args, env=ros_subprocess_env(), stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    client = injector = None
    try:
        namespaces = [_namespace(c.name) for c in PLANT.cells]
        client = FoxgloveClient(port, ready=tuple(f'{ns}/parts' for ns in namespaces),
                                failed=lambda: None if process.poll() is None else
                                f'the plant exited with {process.returncode}: '
                                f'{process.stderr.read()[-3000:]}')
        wanted = [f'{ns}/{name}' for ns in namespaces for name in PER_STEP] + [
            f'{ns}/scene' for ns in namespaces]
        client.wait(lambda: all(client.messages(t) for t in wanted),
                    f'every cell\'s streams and scene reach the client ({wanted})',
                    timeout=CLI_TIMEOUT)
        injector = _FaultInjector(ros_context)
        counts: dict = {}
        for cell, kind, target, params in PLANT_FAULTS:
            injector.inject(cell, kind, target, params)
            counts[cell] = counts.get(cell, 0) + 1
        assert wait_for(lambda: injector.all_expired(counts), CLI_TIMEOUT, injector.executor), \
            'the faults are stated and expire on every cell\'s faults stream'
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=CLI_TIMEOUT)
        assert process.returncode == 0, err[-3000:]
        received = list(client.received)
    finally:
        if injector is not None:
            injector.close()
        if client is not None:
            client.close()
        if process.poll() is None:
            process.kill()
            process.communicate()
    step_ns = round(PLANT.cells[0].cell.settings.step * 1e9)
    outages = {}
    for cell in PLANT.cells:
        messages = recorded(tmp_path / f'{cell.name}.mcap')
        ns = _namespace(cell.name)
        steps = cdr.stamp_of(messages[f'{ns}/parts'][-1]) // step_ns
        silenced = outages[cell.name] = matrix.silenced_steps(
            messages.get(f'{ns}/faults', []), step_ns, steps)
        kinds = {kind for c, kind, _, _ in PLANT_FAULTS if c == cell.name}
        stated = {f.kind for d in messages.get(f'{ns}/faults', [])
                  for f in decode_fault_state(d).active}
        assert stated == kinds, f'{cell.name}: recorded faults {stated}, injected {kinds}'
        for name in PER_STEP:
            topic = f'{ns}/{name}'
            gaps = matrix.step_gaps(messages.get(topic, []), step_ns, steps,
                                    silenced.get('/' + name, set()))
            assert gaps is None, f'{cell.name}: recorded {topic}: {gaps}'
        for name in PER_STEP + ('light_barrier_edges', 'faults'):
            topic = f'{ns}/{name}'
            by_stamp = matrix.by_stamp(messages.get(topic, []))
            for m in (m for m in received if m.topic == topic):
                assert m.data in by_stamp.get(m.log_time, []), \
                    f'Foxglove {topic} at {m.log_time} ns is not what {cell.name} recorded'
    assert len(outages['sorter'].get('/light_barriers', ())) == round(FAULT_DURATION * 1e9
                                                                       / step_ns), \
        'the sorter\'s outage silences light_barriers for its duration'
