"""``conveyor-twin run --opcua/--modbus``: the URLs, bad options, a recording with PLC writes,
a server that dies mid-run."""

import json
from pathlib import Path
import re
import subprocess
import sys
import threading
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rclpy.serialization import deserialize_message

from conveyor_twin.cell import load_cell
from conveyor_twin.health import EXIT_BACKGROUND_FAILURE
from conveyor_twin.plc.tags import tag_map
from conveyor_twin.record import reader
from test.plc.plc_clients import Modbus, OpcUa

pytestmark = pytest.mark.ros

CLI = [sys.executable, '-m', 'conveyor_twin.cli']
OPCUA_LINE = re.compile(r'OPC UA server at (opc\.tcp://\S+)')
MODBUS_LINE = re.compile(r'Modbus TCP server at [\d.]+:(\d+)')
#: Stops the Modbus server's event loop 1 s after it started: its thread dies.
KILL_MODBUS = '''
import sys, threading
from conveyor_twin.plc import modbus_server
start = modbus_server.ModbusServer.start
def start_then_die(self):
    start(self)
    threading.Timer(1.0, lambda: self._loop.call_soon_threadsafe(self._loop.stop)).start()
modbus_server.ModbusServer.start = start_then_die
from conveyor_twin.cli import main
sys.exit(main(sys.argv[1:]))
'''


def test_run_prints_the_urls_and_exits_0(ros_processes, tmp_path):
    process = ros_processes.start(
        CLI + ['run', '--opcua', '0', '--modbus', '0', '--mode', 'fast', '--duration', '2',
               '--quiet', '--opcua-cert-dir', str(tmp_path / 'pki')],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = process.communicate(timeout=300)
    assert process.returncode == 0, err
    assert OPCUA_LINE.search(out) and MODBUS_LINE.search(out), out
    assert (tmp_path / 'pki').is_dir()  # the server's certificate, made on first start


@pytest.mark.parametrize('args, message', [
    (['--opcua', 'localhost:99999'], 'port'),
    (['--modbus', 'a:b:c'], 'IPv6'),
    (['--modbus', ''], 'port'),
    (['--opcua', '0', '--split'], 'composed layout'),
    (['--opcua', '0', '--opcua-user', 'plc'], 'CONVEYOR_TWIN_OPCUA_PASSWORD'),
])
def test_bad_plc_options_exit_2_with_a_message(args, message, capsys, monkeypatch):
    from conveyor_twin.cli.run import main
    monkeypatch.delenv('CONVEYOR_TWIN_OPCUA_PASSWORD', raising=False)
    assert main(['--duration', '1', *args]) == 2
    assert message in capsys.readouterr().err


def test_a_port_in_use_exits_2_and_names_it(ros_processes):
    import socket
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        process = ros_processes.start(
            CLI + ['run', '--modbus', str(port), '--mode', 'fast', '--duration', '1', '--quiet'],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _, err = process.communicate(timeout=300)
    assert process.returncode == 2 and f'127.0.0.1:{port}' in err, err


class _Addresses:
    """Read a run's standard error in a thread (so it never fills); find the server lines
    ``--json`` prints there at start."""

    def __init__(self, process) -> None:
        self.lines = []
        self._thread = threading.Thread(target=self._read, args=(process.stderr,), daemon=True)
        self._thread.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append(line)

    def wait(self, timeout: float = 120.0):
        """Return (OPC UA url, Modbus port) once both lines are out."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            text = ''.join(self.lines)
            url, port = OPCUA_LINE.search(text), MODBUS_LINE.search(text)
            if url and port:
                return url.group(1), int(port.group(1))
            self._thread.join(0.05)
        raise AssertionError(f'no server lines within {timeout} s: {"".join(self.lines)}')

    def text(self) -> str:
        self._thread.join(30)
        return ''.join(self.lines)


def _wait_steps(modbus, at_least, timeout=120.0):
    """Poll the Modbus ``Step`` register until it reaches ``at_least`` (bounded)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        step = modbus.inputs()['Step']
        if step >= at_least:
            return step
        time.sleep(0.01)  # a PLC's poll period
    raise AssertionError(f'the twin did not reach step {at_least} within {timeout} s')


def test_a_recording_with_plc_writes_resimulates_bit_for_bit(ros_processes, tmp_path):
    path = tmp_path / 'plc.mcap'
    process = ros_processes.start(
        CLI + ['run', '--mode', 'realtime', '--duration', '3', '--quiet', '--json',
               '--record', str(path), '--opcua', '0', '--modbus', '0',
               '--opcua-security', 'None'],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stderr = _Addresses(process)
    url, port = stderr.wait()
    tags = tag_map(load_cell())
    modbus, opcua = Modbus(port, tags), OpcUa(url)
    try:
        setpoint = tags.by_path('Belts/main/SpeedSetpoint')
        step = _wait_steps(modbus, 1)
        for value in (0.75, 1.25):
            assert not modbus.write(setpoint, value).isError()
            step = _wait_steps(modbus, step + 100)
            opcua.write_double('Belts/main/SpeedSetpoint', value + 0.25)
            step = _wait_steps(modbus, step + 100)
        assert modbus.write(setpoint, 7.0).isError()  # refused: not recorded
    finally:
        modbus.close()
        opcua.close()
    out = process.stdout.read()
    assert process.wait(300) == 0, stderr.text()
    summary = json.loads(out.splitlines()[-1])
    assert summary['rejected_commands'] == 1 and summary['plc_modbus_writes_accepted'] == 2
    from conveyor_twin.record.resimulate import resimulate
    report = resimulate(str(path))
    assert report.ok, str(report.difference)
    assert report.commands == 4


def test_a_server_that_dies_mid_run_ends_it_with_exit_3(ros_processes, tmp_path):
    path = tmp_path / 'died.mcap'
    process = ros_processes.start(
        [sys.executable, '-c', KILL_MODBUS, 'run', '--mode', 'realtime', '--duration', '60',
         '--quiet', '--json', '--modbus', '0', '--record', str(path)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = process.communicate(timeout=300)
    assert process.returncode == EXIT_BACKGROUND_FAILURE, err
    summary = json.loads(out.splitlines()[-1])
    assert [f['name'] for f in summary['failures']] == ['Modbus server']
    assert summary['sim_time_s'] < 60
    assert 'Modbus server' in err
    last = list(reader.read_messages(str(path), topics=['/diagnostics']))[-1]
    statuses = deserialize_message(last.data, DiagnosticArray).status
    assert any(s.level == DiagnosticStatus.ERROR and 'Modbus server' in s.message
               for s in statuses)


PLANT = Path(__file__).resolve().parents[1] / 'resources' / 'plant' / 'chain.yaml'
CELL_MODBUS_LINE = re.compile(r"\[(\w+)\] conveyor-twin plant: cell '\w+': Modbus TCP server at "
                              r'[\d.]+:(\d+)')


def test_each_cell_of_a_plant_serves_its_own_modbus(ros_processes):
    from conveyor_twin.plant.loader import load_plant
    plant = load_plant(str(PLANT))
    process = ros_processes.start(
        CLI + ['plant', str(PLANT), '--mode', 'realtime', '--duration', '6', '--quiet',
               '--modbus', '0'], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stderr = _Addresses(process)
    deadline = time.monotonic() + 120
    ports = {}
    while len(ports) < 2 and time.monotonic() < deadline:
        ports = {m.group(1): int(m.group(2))
                 for m in CELL_MODBUS_LINE.finditer(''.join(stderr.lines))}
        time.sleep(0.05)  # the poll period of the cells' output
    assert len(ports) >= 2, ''.join(stderr.lines)
    for name, port in sorted(ports.items())[:2]:
        tags = tag_map(plant.cell(name).cell)
        client = Modbus(port, tags)
        try:
            assert _wait_steps(client, 100) >= 100
            assert client.inputs()['Mode'] == 0  # realtime
            # the plant steps its cells: the lockstep handshake is refused
            assert client.write(tags.by_path('Lockstep/Tick'), 1).isError()
        finally:
            client.close()
    process.stdout.read()
    assert process.wait(300) == 0, stderr.text()


def test_plant_plc_options_are_checked_before_anything_starts(capsys):
    from conveyor_twin.cli.plant import main
    assert main([str(PLANT), '--composed', '--modbus', '0']) == 2
    assert 'not with --composed' in capsys.readouterr().err
    assert main([str(PLANT), '--opcua', '65534']) == 2
    assert '65536' in capsys.readouterr().err  # cell 2 would serve at 65534 + 2


def test_a_plant_cell_serves_at_the_base_port_plus_its_index():
    from conveyor_twin.plc.options import PlcOptions
    options = PlcOptions(opcua='0.0.0.0:4840', modbus='5020')
    assert options.for_cell(2) == PlcOptions(opcua='0.0.0.0:4842', modbus='5022')
    assert PlcOptions(modbus='0').for_cell(3).modbus == '0'


def test_the_opcua_password_comes_from_the_environment(monkeypatch):
    from conveyor_twin.cli.run import build_parser, plc_options
    monkeypatch.setenv('CONVEYOR_TWIN_OPCUA_PASSWORD', 's3cret')
    args = build_parser().parse_args(['--opcua', '4840', '--opcua-user', 'plc',
                                      '--plc-read-only', '--opcua-security', 'None'])
    options = plc_options(args)
    assert (options.opcua, options.modbus, options.user, options.password) == (
        '4840', '', 'plc', 's3cret')
    assert options.read_only and options.security == 'None'
    assert plc_options(build_parser().parse_args([])) is None
