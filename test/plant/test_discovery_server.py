"""The Fast DDS discovery server of a plant: the option's values are checked before anything
starts, the server process is supervised (killed: reported once, with its exit status; stopped:
not a failure), and a plant of processes on one host that discovers only through it gives the
bits of the plant in one process.

A client of a discovery server ignores its loopback peers: pointed at a port where no server
runs, the cells of a plant never see each other. So a plant that completes through the server
discovered through it."""

import json
import os
from pathlib import Path
import signal
import socket
import subprocess
import sys

import pytest

from conveyor_twin.health import Health
from conveyor_twin.plant.discovery import (client_environment, DiscoveryAddress,
                                           DiscoveryError, DiscoveryServer,
                                           parse_discovery_server)
from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.runner import PlantRunner
from conveyor_twin.testing.ros_env import claim_domain_id

from .test_plant_cli import is_progress, Lines, progress

CHAIN = Path(__file__).resolve().parents[1] / 'resources' / 'plant' / 'chain.yaml'
STEPS = 1500
TIMEOUT = 240.0         # s, a bound for a loaded machine, not a speed requirement


def server_port() -> int:
    """A UDP port for this test process's server: below Fast DDS' ports (7400 and up), above
    the privileged ones, one per ROS domain id (which no other process on this machine holds)."""
    return 6400 + claim_domain_id()


def cli(*args: str) -> list:
    return [sys.executable, '-m', 'conveyor_twin.cli', 'plant', *args]


@pytest.mark.parametrize('text, start, address', [
    ('start', True, ('127.0.0.1', 11811)),
    ('start:11900', True, ('127.0.0.1', 11900)),
    ('start:10.0.0.1:11811', True, ('10.0.0.1', 11811)),
    ('11811', False, ('127.0.0.1', 11811)),
    ('cell-host.lan:11811', False, ('cell-host.lan', 11811)),
    ('starter:11811', False, ('starter', 11811)),
])
def test_the_option_names_a_server_to_use_or_to_start(text, start, address):
    setting = parse_discovery_server(text)
    assert setting.start is start and setting.address == DiscoveryAddress(*address)


@pytest.mark.parametrize('text, message', [
    ('', "got ''; expected [HOST:]PORT (use the server there) or start[:[HOST:]PORT]"),
    ('start:', "got 'start:'; expected [HOST:]PORT, HOST an IPv4 address or a host name, "
               'PORT an integer in [1, 65535]'),
    ('10.0.0.1:0', "got '10.0.0.1:0'; expected [HOST:]PORT"),
    ('host:70000', "got 'host:70000'; expected"),
    ('[::1]:11811', "got '[::1]:11811' (host '[::1]'); expected [HOST:]PORT"),
])
def test_a_bad_value_is_refused_naming_the_option_and_the_value(text, message):
    with pytest.raises(DiscoveryError, match='^--discovery-server: ') as exc:
        parse_discovery_server(text)
    assert message in str(exc.value)


def test_clients_of_a_server_on_every_interface_use_loopback():
    assert client_environment(DiscoveryAddress('0.0.0.0', 11811)) == {
        'ROS_DISCOVERY_SERVER': '127.0.0.1:11811'}
    assert client_environment(DiscoveryAddress('10.0.0.1', 11811), super_client=True) == {
        'ROS_DISCOVERY_SERVER': '10.0.0.1:11811', 'ROS_SUPER_CLIENT': 'TRUE'}


@pytest.mark.parametrize('args, message', [
    (['--discovery-server', 'nowhere'], "--discovery-server: got 'nowhere'"),
    (['--cell', 'first', '--discovery-server', 'start'],
     '--discovery-server start: a cell process uses a server'),
])
def test_the_cli_refuses_a_bad_option_before_anything_starts(args, message):
    proc = subprocess.run(cli(str(CHAIN), *args), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and proc.stdout == '', proc.stderr
    assert message in proc.stderr


def test_a_killed_server_is_reported_once_and_a_stopped_one_is_not():
    failures = []
    health = Health(printer=failures.append)
    address = DiscoveryAddress('127.0.0.1', server_port())
    server = DiscoveryServer(address, health=health)
    server.start()
    try:
        assert server.alive() and health.ok
        os.kill(server.pid, signal.SIGKILL)
        assert health.event.wait(TIMEOUT)
    finally:
        server.stop()
    (failure,) = health.failures
    assert failure.name == 'discovery server'
    assert failure.error.startswith(f'{address}: exit status -9 (killed by SIGKILL); last '
                                    'output: ')
    assert len(failures) == 1 and 'discovery server failed' in failures[0]
    # a server stopped by its owner ended as asked: nothing to report
    calm = Health(printer=failures.append)
    again = DiscoveryServer(address, health=calm)
    again.start()
    again.stop()
    assert calm.ok and not again.alive() and len(failures) == 1


def test_a_server_that_cannot_listen_is_an_error_naming_its_address():
    health = Health(printer=lambda text: None)
    address = DiscoveryAddress('127.0.0.1', server_port())
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind((address.host, address.port))
        server = DiscoveryServer(address, health=health)
        with pytest.raises(DiscoveryError, match=f'^discovery server on {address} did not '
                           r'start \(exit status 1\): '):
            server.start()
    assert not server.alive() and health.ok


@pytest.mark.ros
def test_a_plant_of_processes_through_the_server_gives_the_bits_of_one_process(
        ros_processes):
    port = server_port()
    proc = ros_processes.start(cli(str(CHAIN), '--processes', '--no-streams', '--duration',
                                   str(STEPS / 1000), '--json', '--discovery-server',
                                   f'start:127.0.0.1:{port}'),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, err
    assert f'discovery server at 127.0.0.1:{port} (pid ' in err
    summary = json.loads(out)
    runner = PlantRunner(load_plant(CHAIN))
    runner.run_to(STEPS)
    assert summary['steps'] == {'feeder': STEPS, 'first': STEPS, 'second': STEPS}
    assert summary['state_hashes'] == runner.state_hashes()
    assert summary['failures'] == []


@pytest.mark.ros
def test_the_plant_reports_its_server_killed_and_runs_on(ros_processes):
    port = server_port()
    proc = ros_processes.start(cli(str(CHAIN), '--no-streams', '--duration', '0', '--json',
                                   '--discovery-server', f'start:127.0.0.1:{port}'),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    err = Lines(proc.stderr)
    line = err.wait(lambda x: 'discovery server at ' in x, 'naming the server')
    pid = int(line.rpartition('(pid ')[2].rstrip(')'))
    err.wait(lambda x: is_progress(x) and progress(x)['time'] > 0, 'with the plant running')
    os.kill(pid, signal.SIGKILL)
    err.wait(lambda x: 'conveyor_twin: discovery server failed: 127.0.0.1:' in x
             and 'exit status -9 (killed by SIGKILL)' in x, 'reporting the server')
    # the cells found each other already: the plant runs on
    before = progress(err.wait(is_progress, 'after the report'))['time']
    err.wait(lambda x: is_progress(x) and progress(x)['time'] > before, 'further on')
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 3
    summary = json.loads(out)
    assert [f.split(':')[0] for f in summary['failures']] == ['discovery server']
    assert summary['dead'] == []
