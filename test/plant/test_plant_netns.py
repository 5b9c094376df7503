"""Cells in separate network namespaces, coupled only through a virtual Ethernet pair over UDP
(no shared memory), discovering each other as on two hosts (loopback range plus
``ROS_STATIC_PEERS``): the plant gives the bits of all cells in one process.

Needs ``unshare -rn`` (an unprivileged user and network namespace) and ``ip``; skipped where
the machine does not allow them."""

from pathlib import Path
import shutil
import subprocess
import sys

import pytest

from conveyor_twin.plant.loader import load_plant
from conveyor_twin.plant.runner import PlantRunner

ROOT = Path(__file__).resolve().parents[2]
CHAIN = ROOT / 'test' / 'resources' / 'plant' / 'chain.yaml'
STEPS = 1500
TIMEOUT = 300.0   # s, a bound for a loaded machine

# Runs inside `unshare -rn`: this namespace holds feeder and first (10.77.0.1), a second one
# holds `second` (10.77.0.2); a veth pair joins them. UDP only: shared memory would bypass it.
SCRIPT = '''set -e
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
ROS_STATIC_PEERS=10.77.0.2 $RUN --cell feeder > {out}/feeder.json &
A=$!
ROS_STATIC_PEERS=10.77.0.2 $RUN --cell first > {out}/first.json &
B=$!
nsenter -t $HOLDER -n env ROS_STATIC_PEERS=10.77.0.1 $RUN --cell second > {out}/second.json &
C=$!
wait $A $B $C
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


pytestmark = [pytest.mark.ros,
              pytest.mark.skipif(not namespaces_allowed(),
                                 reason='no unprivileged network namespaces here')]


def test_cells_in_separate_network_namespaces_give_the_bits_of_one_process(
        ros_processes, tmp_path):
    import json
    script = tmp_path / 'plant.sh'
    script.write_text(SCRIPT.format(timeout=int(TIMEOUT), python=sys.executable, plant=CHAIN,
                                    duration=STEPS / 1000, out=tmp_path))
    proc = ros_processes.start(['unshare', '-rn', '--fork', 'bash', str(script)],
                               cwd=str(ROOT), stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    out, _ = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, out
    runner = PlantRunner(load_plant(CHAIN))
    runner.run_to(STEPS)
    for name, digest in runner.state_hashes().items():
        lines = (tmp_path / f'{name}.json').read_text().strip().splitlines()
        final = json.loads(lines[-1])
        assert final['step'] == STEPS and final['state_hash'] == digest, name
    assert runner.ledger().links['first_second'].inserted > 0
