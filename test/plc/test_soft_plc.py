"""examples/plc/soft_plc.py: the soft PLC stops and restarts the belt through each protocol.

The PLC steps a lockstep twin itself (OPC UA ``Lockstep/Step``, Modbus ``Lockstep/Tick``), so
the run does not depend on the machine's speed; parts placed before ``lb_infeed`` give it
something to act on within a second of simulation time.
"""

import json
from pathlib import Path
import subprocess
import sys

import pytest

from conveyor_twin.plc.options import PlcOptions
from conveyor_twin.testing import LockstepTwin

pytestmark = pytest.mark.ros

SOFT_PLC = Path(__file__).resolve().parents[2] / 'examples' / 'plc' / 'soft_plc.py'


class Commands:
    """A frame sink keeping the commands that took effect: (step, sender, belt, value)."""

    def __init__(self) -> None:
        self.log = []

    def on_frame(self, frame) -> None:
        if frame.commands:
            self.log.extend((frame.step, c.sender, c.name, c.value) for c in frame.commands)


@pytest.mark.parametrize('protocol, security', [('opcua', 'Basic256Sha256'),
                                                ('modbus', 'None')])
def test_the_soft_plc_stops_and_restarts_the_belt(protocol, security, tmp_path):
    plc = PlcOptions(security=security, cert_dir=str(tmp_path / 'server_pki'))
    address = {'opcua': '0'} if protocol == 'opcua' else {'modbus': '0'}
    with LockstepTwin(seed=3, plc=plc, **address) as twin:
        commands = Commands()
        twin.composed.output.subscribe(commands)
        twin.spawn('spacer', [1.8, 1.6], [0.0, 0.1])
        where = (['--url', twin.plc.opcua_url, '--security', security, '--cert-dir',
                  str(tmp_path / 'client_pki')] if protocol == 'opcua'
                 else ['--port', str(twin.plc.modbus_port)])
        done = subprocess.run(
            [sys.executable, str(SOFT_PLC), protocol, *where, '--barrier', 'lb_infeed',
             '--pause', '0.3', '--lockstep', '--sim-duration', '1.5'],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        result = json.loads(done.stdout.splitlines()[-1])
        twin.composed.output.unsubscribe(commands)
    assert result['stops'] >= 1 and result['restarts'] >= 1, result
    assert result['sim_time'] >= 1.5
    values = [value for _, sender, belt, value in commands.log
              if sender.startswith(protocol) and belt == 'main']
    assert values[:2] == [0.0, 0.5], commands.log
    assert len(values) == result['stops'] + result['restarts']
