"""Cells in separate network namespaces, coupled only through a virtual Ethernet pair over UDP
(no shared memory), as on two hosts: the plant gives the bits of all cells in one process,
whether the cells discover each other through ``ROS_STATIC_PEERS`` or, with multicast unable to
cross the pair, through a Fast DDS discovery server.

Needs ``unshare -rn`` (an unprivileged user and network namespace) and ``ip`` (the discovery
server variant also ``tc`` with htb and u32); skipped where the machine does not allow them."""

import json
from pathlib import Path
import os
import re
import shutil
import signal
import subprocess
import sys

import pytest

from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.runner import PlantRunner

ROOT = Path(__file__).resolve().parents[2]
CHAIN = ROOT / 'test' / 'resources' / 'plant' / 'chain.yaml'
STEPS = 1500
TIMEOUT = 300.0   # s, a bound for a loaded machine
STOP_GRACE = 30.0  # s, for the processes to print their summaries after SIGTERM
SERVER = '10.77.0.1:11811'

# Runs inside `unshare -rn`: this namespace holds feeder and first (10.77.0.1), a second one
# holds `second` (10.77.0.2); a veth pair joins them. UDP only: shared memory would bypass it.
NAMESPACES = '''set -e
ip link set lo up
ip link add va type veth peer name vb
unshare -n sleep {timeout} & HOLDER=$!
# the holder has its own network namespace once unshare has run (no fixed wait: a loaded
# machine may take long)
while [ "$(readlink /proc/$HOLDER/ns/net)" = "$(readlink /proc/$$/ns/net)" ]; do sleep 0.05; done
ip link set vb netns $HOLDER
ip addr add 10.77.0.1/24 dev va
ip link set va up
nsenter -t $HOLDER -n sh -c 'ip link set lo up; ip addr add 10.77.0.2/24 dev vb; ip link set vb up'
export FASTDDS_BUILTIN_TRANSPORTS=UDPv4
RUN="{python} -m conveyor_twin.cli plant {plant} --duration {duration} --no-streams --run-id 1"
'''

STATIC_PEERS = NAMESPACES + '''
ROS_STATIC_PEERS=10.77.0.2 $RUN --cell feeder > {out}/feeder.json &
A=$!
ROS_STATIC_PEERS=10.77.0.2 $RUN --cell first > {out}/first.json &
B=$!
nsenter -t $HOLDER -n env ROS_STATIC_PEERS=10.77.0.1 $RUN --cell second > {out}/second.json &
C=$!
wait $A $B $C
kill $HOLDER
'''

# Each end of the pair sends through htb classes: 1:3 takes every IPv4 multicast frame and
# drops it (a pfifo of length 0), 1:2 counts the UDP datagrams to the server's port, 1:1 the
# rest. Routes cannot stop multicast: a socket that names its outgoing interface
# (IP_MULTICAST_IF, as Fast DDS does) sends on it without one.
SHAPE = '''shape() {{
  tc qdisc add dev $1 root handle 1: htb default 1
  for c in 1 2 3; do tc class add dev $1 parent 1: classid 1:$c htb rate 10gbit 2>/dev/null; done
  tc qdisc add dev $1 parent 1:3 handle 3: pfifo limit 0
  tc filter add dev $1 parent 1: protocol ip pref 1 u32 match ip dst 224.0.0.0/4 flowid 1:3
  tc filter add dev $1 parent 1: protocol ip pref 2 u32 match ip protocol 17 0xff \\
    match ip dport {port} 0xffff flowid 1:2
}}
'''

# No static peers: the loopback range gives each process 127.0.0.1 as its only peer, and a
# client of a discovery server ignores even that. The server runs with the plant's monitor in
# the first namespace (the recipe of docs/plant.md); every cell is pointed at it.
DISCOVERY_SERVER = NAMESPACES + SHAPE + '''
export -f shape
shape va
nsenter -t $HOLDER -n bash -c 'shape vb'
# the shaping at work: one multicast datagram sent out of va is dropped there
{python} -c "import socket; s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); \\
s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton('10.77.0.1')); \\
s.sendto(b'probe', ('239.255.0.1', 7400))"
unset ROS_STATIC_PEERS
{python} -m conveyor_twin.cli plant {plant} --monitor --duration {duration} --json --quiet \\
  --discovery-server start:{server} > {out}/monitor.json 2> {out}/monitor.err &
M=$!
$RUN --cell feeder --discovery-server {server} > {out}/feeder.json &
A=$!
$RUN --cell first --discovery-server {server} > {out}/first.json &
B=$!
nsenter -t $HOLDER -n $RUN --cell second --discovery-server {server} > {out}/second.json &
C=$!
wait $A $B $C
wait $M || {{ echo "monitor exit status $?"; cat {out}/monitor.err; exit 1; }}
tc -s class show dev va > {out}/tc_first_namespace.txt
nsenter -t $HOLDER -n tc -s class show dev vb > {out}/tc_second_namespace.txt
kill $HOLDER
'''


def namespaces_allowed() -> bool:
    if shutil.which('unshare') is None or shutil.which('ip') is None:
        return False
    try:
        probe = subprocess.run(['unshare', '-rn', 'ip', 'link', 'add', 'va', 'type', 'veth',
                                'peer', 'name', 'vb'], capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


def traffic_control_allowed() -> bool:
    """True if a namespace may shape its veth with htb classes and u32 filters."""
    if not namespaces_allowed() or shutil.which('tc') is None:
        return False
    try:
        probe = subprocess.run(
            ['unshare', '-rn', 'bash', '-c', SHAPE.format(port=11811)
             + 'set -e; ip link add va type veth peer name vb; shape va'],
            capture_output=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


pytestmark = [pytest.mark.ros,
              pytest.mark.skipif(not namespaces_allowed(),
                                 reason='no unprivileged network namespaces here')]


def run_in_namespaces(ros_processes, tmp_path: Path, script: str) -> None:
    path = tmp_path / 'plant.sh'
    path.write_text(script.format(timeout=int(TIMEOUT), python=sys.executable, plant=CHAIN,
                                  duration=STEPS / 1000, out=tmp_path, server=SERVER,
                                  port=SERVER.rpartition(':')[2]))
    proc = ros_processes.start(['unshare', '-rn', '--fork', 'bash', str(path)],
                               cwd=str(ROOT), stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    try:
        out, _ = proc.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:  # end it as a user would; show what each process said
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            out, _ = proc.communicate(timeout=STOP_GRACE)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate()
        pytest.fail(f'the plant did not end within {TIMEOUT:.0f} s; ended with SIGTERM\n'
                    f'{out}\n{_outputs(tmp_path)}')
    assert proc.returncode == 0, f'{out}\n{_outputs(tmp_path)}'


def _outputs(tmp_path: Path) -> str:
    """The end of every file the processes wrote (their summaries and error output)."""
    parts = []
    for f in sorted(tmp_path.iterdir()):
        if f.suffix in ('.json', '.err', '.txt'):
            parts.append(f'--- {f.name}:\n{f.read_text(errors="replace")[-4000:]}')
    return '\n'.join(parts)


def assert_bits_of_one_process(tmp_path: Path) -> None:
    runner = PlantRunner(load_plant(CHAIN))
    runner.run_to(STEPS)
    for name, digest in runner.state_hashes().items():
        lines = (tmp_path / f'{name}.json').read_text().strip().splitlines()
        final = json.loads(lines[-1])
        assert final['step'] == STEPS and final['state_hash'] == digest, name
    assert runner.ledger().links['first_second'].inserted > 0


def htb_class(text: str, classid: str) -> dict:
    """The packets sent and dropped of one class in ``tc -s class show``."""
    m = re.search(rf'class htb {classid} .*?\n\s*Sent (\d+) bytes (\d+) pkt \(dropped (\d+)',
                  text)
    assert m, text
    return {'sent': int(m.group(2)), 'dropped': int(m.group(3))}


def test_cells_in_separate_network_namespaces_give_the_bits_of_one_process(
        ros_processes, tmp_path):
    run_in_namespaces(ros_processes, tmp_path, STATIC_PEERS)
    assert_bits_of_one_process(tmp_path)


@pytest.mark.skipif(not traffic_control_allowed(), reason='no tc htb/u32 in a namespace here')
def test_cells_discover_each_other_through_the_discovery_server_without_multicast(
        ros_processes, tmp_path):
    run_in_namespaces(ros_processes, tmp_path, DISCOVERY_SERVER)
    assert_bits_of_one_process(tmp_path)
    # Discovery went through the server: the second namespace was given no address of the
    # first but the server's, no multicast frame crossed the pair (class 1:3 drops every one:
    # the probe's, and none of the plant's), and the second namespace's cell sent datagrams
    # to the server's port.
    first = (tmp_path / 'tc_first_namespace.txt').read_text()
    second = (tmp_path / 'tc_second_namespace.txt').read_text()
    assert htb_class(first, '1:3') == {'sent': 0, 'dropped': 1}, first
    assert htb_class(second, '1:3') == {'sent': 0, 'dropped': 0}, second
    assert htb_class(second, '1:2')['sent'] > 0, second
    # the monitor that ran the server saw every cell done, with the same bits
    monitor = json.loads((tmp_path / 'monitor.json').read_text())
    assert monitor['failures'] == [] and monitor['layout'] == 'monitor'
    assert monitor['steps'] == {'feeder': STEPS, 'first': STEPS, 'second': STEPS}
    finals = {n: json.loads((tmp_path / f'{n}.json').read_text().strip().splitlines()[-1])
              for n in monitor['steps']}
    assert monitor['state_hashes'] == {n: f['state_hash'] for n, f in finals.items()}
