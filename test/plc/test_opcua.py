"""The OPC UA server against a real asyncua client on 127.0.0.1 (no ROS).

Each rig is a core twin (``build_twin`` + ``TwinOutput`` + ``PlcState``) with a ``Runner`` in
fast or lockstep mode and an :class:`OpcUaServer` on a free port; starting asyncua is slow, so
the rigs are shared per module.
"""

import asyncio
import math
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

from asyncua import Client, ua
from asyncua.crypto import cert_gen
from asyncua.ua.uaerrors import UaStatusCodeError
from cryptography import x509
from cryptography.hazmat.primitives import serialization
from cryptography.x509.oid import ExtendedKeyUsageOID
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.health import Health
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import CoordinatorOutput, MacroOutput, MicroOutput
from conveyor_twin.plc.address import PlcServerError
from conveyor_twin.plc.lockstep import StepHandshake
from conveyor_twin.plc.opcua_nodes import EPOCH, NAMESPACE, sim_datetime
from conveyor_twin.plc.opcua_security import server_certificate
from conveyor_twin.plc.opcua_server import HEALTH_NAME, OpcUaSecurity, OpcUaServer
from conveyor_twin.plc.state import PlcState
from conveyor_twin.plc.tags import tag_map
from conveyor_twin.plc.writes import PlcWriter
from conveyor_twin.wire.decoders import decode_light_barrier_edge

#: Generous bound of every wait on a condition [s] (a loaded machine is slow, never wrong).
BUDGET = 120.0
CLIENT_URI = 'urn:conveyor-twin:test-client'
USER, PASSWORD = 'plc', 'secret-1'


def wait_for(condition: Callable[[], bool], what: str, budget: float = BUDGET) -> None:
    end = time.monotonic() + budget
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f'not within {budget} s: {what}')
        time.sleep(0.01)


class EdgeSink:
    """Counts every edge of the frames (the truth the OPC UA counters are checked against)."""

    def __init__(self) -> None:
        self.edges: List[Tuple[int, bytes]] = []
        self.step = 0

    def on_frame(self, frame: Any) -> None:
        if frame.edges:
            self.edges.extend(frame.edges)
        self.step = frame.step

    def per_barrier(self) -> Dict[str, Dict[str, Any]]:
        out: Dict[str, Dict[str, Any]] = {}
        for stamp, data in list(self.edges):
            edge = decode_light_barrier_edge(data)
            b = out.setdefault(edge.name, {'rising': 0, 'falling': 0, 'last_rising': None,
                                           'last_falling': None, 'blocked': False})
            key = 'rising' if edge.blocked else 'falling'
            b[key] += 1
            b['last_' + key] = stamp
            b['blocked'] = edge.blocked
        return out


class Rig:
    """A core twin with its PLC state, writer, handshake, runner and OPC UA server."""

    def __init__(self, mode: TimeMode, security: OpcUaSecurity, *, seed: int = 1,
                 max_steps: Optional[int] = None) -> None:
        self.built = build_twin(load_cell(), seed=seed)
        twin = self.built.twin
        self.output = TwinOutput([CoordinatorOutput(twin), MicroOutput(self.built.micro),
                                  MacroOutput(self.built.macro)])
        twin.step_listeners.append(self.output.on_step)
        self.sink = EdgeSink()
        self.output.subscribe(self.sink)
        self.runner = Runner(twin, mode, max_steps=max_steps)
        self.handshake = StepHandshake(self.runner.step,
                                       mode_is_lockstep=mode is TimeMode.LOCKSTEP,
                                       index=lambda: twin.step_index)
        self.state = PlcState(self.built.cell, mode=mode.value, handshake=self.handshake,
                              rejected=lambda: twin.commands.rejected_total)
        self.output.subscribe(self.state)
        self.writer = PlcWriter(twin.commands, sender='opcua', read_only=security.read_only)
        self.server = OpcUaServer(self.state, self.writer, self.handshake, host='127.0.0.1',
                                  port=0, health=twin.health, security=security)
        self.server.start()

    def close(self) -> None:
        self.runner.stop()
        self.server.stop()


def client_files(folder: str) -> Tuple[str, str]:
    """Write a client certificate and key into ``folder``; return their paths."""
    key = cert_gen.generate_private_key()
    cert = cert_gen.generate_self_signed_app_certificate(
        key, 'test client', {}, [x509.UniformResourceIdentifier(CLIENT_URI)],
        extended=[ExtendedKeyUsageOID.CLIENT_AUTH], days=2)
    cert_path, key_path = os.path.join(folder, 'client.der'), os.path.join(folder, 'client.pem')
    with open(cert_path, 'wb') as f:
        f.write(cert.public_bytes(serialization.Encoding.DER))
    with open(key_path, 'wb') as f:
        f.write(cert_gen.dump_private_key_as_pem(key))
    return cert_path, key_path


async def connect(url: str, *, encrypt: Optional[Tuple[str, str]] = None,
                  user: str = '', password: str = '') -> Client:
    client = Client(url, timeout=60)
    client.application_uri = CLIENT_URI
    if user:
        client.set_user(user)
        client.set_password(password)
    if encrypt is not None:
        await client.set_security_string(
            f'Basic256Sha256,SignAndEncrypt,{encrypt[0]},{encrypt[1]}')
    await client.connect()
    return client


def var(client: Client, idx: int, path: str) -> Any:
    return client.get_node(ua.NodeId(f'Twin/{path}', idx))


async def call_step(client: Client, idx: int, n: Any) -> int:
    lock = client.get_node(ua.NodeId('Twin/Lockstep', idx))
    variant = n if isinstance(n, ua.Variant) else ua.Variant(n, ua.VariantType.UInt32)
    return await lock.call_method(ua.NodeId('Twin/Lockstep/Step', idx), variant)


@pytest.fixture(scope='module')
def client_cert(tmp_path_factory) -> Tuple[str, str]:
    return client_files(str(tmp_path_factory.mktemp('client')))


@pytest.fixture(scope='module')
def fast_rig():
    rig = Rig(TimeMode.FAST, OpcUaSecurity(policy='None'), max_steps=4000)
    yield rig
    rig.close()


@pytest.fixture(scope='module')
def secure_rig(tmp_path_factory):
    """Lockstep, Basic256Sha256 and a user: the default security."""
    folder = str(tmp_path_factory.mktemp('server'))
    rig = Rig(TimeMode.LOCKSTEP, OpcUaSecurity(cert_dir=folder, user=USER, password=PASSWORD))
    yield rig
    rig.close()


# --- values ---------------------------------------------------------------------------------

def test_every_edge_counted_at_a_10ms_poll(fast_rig):
    rig = fast_rig
    cell = rig.built.cell
    names = [lb.name for lb in cell.light_barriers]
    polled: List[Dict[str, Tuple[int, int]]] = []

    async def poll() -> Dict[str, Any]:
        client = await connect(rig.server.url)
        try:
            idx = await client.get_namespace_index(NAMESPACE)
            counters = [(var(client, idx, f'Barriers/{n}/RisingEdges'),
                         var(client, idx, f'Barriers/{n}/FallingEdges')) for n in names]
            step = var(client, idx, 'Step')
            rig.runner.start()
            while True:  # a 10 ms poll while the twin runs
                values = await client.read_values([c for pair in counters for c in pair])
                polled.append({n: (values[2 * i], values[2 * i + 1])
                               for i, n in enumerate(names)})
                if not rig.runner.running and await step.read_value() == rig.sink.step:
                    break
                await asyncio.sleep(0.01)
            out = {}
            for n in names:
                prefix = f'Barriers/{n}/'
                rising = await var(client, idx, prefix + 'LastRisingTime').read_data_value()
                falling = await var(client, idx, prefix + 'LastFallingTime').read_data_value()
                out[n] = {
                    'rising': await var(client, idx, prefix + 'RisingEdges').read_value(),
                    'falling': await var(client, idx, prefix + 'FallingEdges').read_value(),
                    'blocked': await var(client, idx, prefix + 'Blocked').read_value(),
                    'last_rising': rising, 'last_falling': falling}
            out['step'] = await step.read_data_value()
            return out
        finally:
            await client.disconnect()

    seen = asyncio.run(poll())
    assert rig.runner.steps_done == 4000 and rig.sink.step == 4000
    truth = rig.sink.per_barrier()
    assert sum(b['rising'] + b['falling'] for b in truth.values()) > 0, 'no edges in the run'
    for n in names:
        expect = truth.get(n, {'rising': 0, 'falling': 0, 'last_rising': None,
                               'last_falling': None, 'blocked': False})
        got = seen[n]
        assert (got['rising'], got['falling']) == (expect['rising'], expect['falling']), n
        assert got['blocked'] == expect['blocked'], n
        for key in ('last_rising', 'last_falling'):
            dv = got[key]
            if expect[key] is None:
                assert dv.Value.Value == 0.0
                continue
            assert dv.Value.Value == expect[key] * 1e-9, (n, key)
            assert dv.SourceTimestamp == sim_datetime(expect[key]), (n, key)
            assert dv.ServerTimestamp.year > 2000
    # the counters polled during the run only grow
    for n in names:
        series = [p[n] for p in polled]
        assert all(a[0] <= b[0] and a[1] <= b[1] for a, b in zip(series, series[1:])), n
    step = seen['step']
    assert step.Value.Value == 4000
    assert step.SourceTimestamp == sim_datetime(4000 * rig.built.twin.dt_ns)
    assert step.SourceTimestamp > EPOCH
    assert len(polled) > 1
    assert rig.built.twin.health.ok


def test_a_stalled_or_killed_client_does_not_stall_the_twin(fast_rig):
    rig = fast_rig
    if not rig.runner.running and rig.runner.steps_done == 0:
        rig.runner.start()
    wait_for(lambda: not rig.runner.running, 'the first run ends')
    paths = [t.path for t in rig.server.tags]
    script = textwrap.dedent(f'''
        import asyncio, os, signal, sys
        from asyncua import Client, ua
        async def main():
            client = Client({rig.server.url!r}, timeout=60)
            await client.connect()
            idx = await client.get_namespace_index({NAMESPACE!r})
            sub = await client.create_subscription(10, None)
            nodes = [client.get_node(ua.NodeId('Twin/' + p, idx)) for p in {paths!r}]
            await sub.subscribe_data_change(nodes)
            print('subscribed', flush=True)
            os.kill(os.getpid(), signal.SIGSTOP)  # stops reading: a stalled client
        asyncio.run(main())
    ''')
    child = subprocess.Popen([sys.executable, '-c', script], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == 'subscribed'
        wait_for(lambda: _stopped(child.pid), 'the client stopped')
        updates = rig.server.updates
        runner = Runner(rig.built.twin, TimeMode.FAST, max_steps=20000)
        runner.start()
        assert runner.wait(BUDGET), 'the twin stalled behind a stalled client'
        assert runner.steps_done == 20000
        wait_for(lambda: rig.server.updates > updates + 10, 'the server keeps updating')
        os.kill(child.pid, signal.SIGKILL)  # and then dies without a goodbye
        child.wait(BUDGET)
        step = rig.built.twin.step_index

        async def read() -> int:
            client = await connect(rig.server.url)
            try:
                idx = await client.get_namespace_index(NAMESPACE)
                return await var(client, idx, 'Step').read_value()
            finally:
                await client.disconnect()
        wait_for(lambda: asyncio.run(read()) == step, 'another client reads the last step')
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(BUDGET)
    assert rig.built.twin.health.ok


def _stopped(pid: int) -> bool:
    with open(f'/proc/{pid}/stat', 'rb') as f:
        stat = f.read()
    return stat[stat.rfind(b')') + 2:stat.rfind(b')') + 3] == b'T'


# --- lockstep, writes and security ----------------------------------------------------------

def test_step_advances_exactly_n_and_matches_direct_stepping(secure_rig, client_cert):
    rig = secure_rig
    start = rig.built.twin.step_index
    assert start == 0, 'runs before any write of this module (file order)'

    async def steps() -> Tuple[List[int], Dict[str, float]]:
        client = await connect(rig.server.url, encrypt=client_cert, user=USER,
                               password=PASSWORD)
        try:
            idx = await client.get_namespace_index(NAMESPACE)
            got = [await call_step(client, idx, n) for n in (1, 499, 1500)]
            times = {}
            for lb in rig.built.cell.light_barriers:
                for key in ('LastRisingTime', 'LastFallingTime', 'RisingEdges'):
                    times[f'{lb.name}/{key}'] = await var(
                        client, idx, f'Barriers/{lb.name}/{key}').read_value()
            times['done'] = await var(client, idx, 'Lockstep/Done').read_value()
            return got, times
        finally:
            await client.disconnect()

    got, seen = asyncio.run(steps())
    assert got == [1, 500, 2000]
    assert rig.built.twin.step_index == 2000 and rig.sink.step == 2000
    assert seen.pop('done') is True
    reference = build_twin(load_cell(), seed=1)
    output = TwinOutput([CoordinatorOutput(reference.twin), MicroOutput(reference.micro),
                         MacroOutput(reference.macro)])
    reference.twin.step_listeners.append(output.on_step)
    direct = EdgeSink()  # the same seed, stepped directly, no server
    output.subscribe(direct)
    reference.step(2000)
    truth = direct.per_barrier()
    assert truth == rig.sink.per_barrier()
    for lb in rig.built.cell.light_barriers:
        b = truth.get(lb.name, {'rising': 0, 'last_rising': None, 'last_falling': None})
        assert seen[f'{lb.name}/RisingEdges'] == b['rising']
        for key, tag in (('last_rising', 'LastRisingTime'), ('last_falling', 'LastFallingTime')):
            expect = b[key] * 1e-9 if b[key] is not None else 0.0
            assert seen[f'{lb.name}/{tag}'] == expect


def test_written_setpoint_is_in_the_belt_state_at_the_next_step(secure_rig, client_cert):
    rig = secure_rig
    twin = rig.built.twin

    async def write_and_step() -> Tuple[float, float]:
        client = await connect(rig.server.url, encrypt=client_cert, user=USER,
                               password=PASSWORD)
        try:
            idx = await client.get_namespace_index(NAMESPACE)
            setpoint = var(client, idx, 'Belts/main/SpeedSetpoint')
            await setpoint.write_value(ua.Variant(0.125, ua.VariantType.Double))
            before = float(twin.actuation.belt_target[0])  # queued, not applied yet
            step = await call_step(client, idx, 1)
            assert step == twin.step_index
            return before, await setpoint.read_value()
        finally:
            await client.disconnect()

    accepted = rig.writer.accepted
    before, shown = asyncio.run(write_and_step())
    assert before != 0.125
    assert float(twin.actuation.belt_target[0]) == 0.125
    assert shown == 0.125
    assert rig.writer.accepted == accepted + 1


@pytest.mark.parametrize('path, value, status', [
    ('Belts/main/SpeedSetpoint', ua.Variant(99.0, ua.VariantType.Double), 'BadOutOfRange'),
    ('Belts/main/SpeedSetpoint', ua.Variant(math.nan, ua.VariantType.Double), 'BadOutOfRange'),
    ('Belts/main/SpeedSetpoint', ua.Variant('fast', ua.VariantType.String), 'BadTypeMismatch'),
    ('Belts/main/SpeedSetpoint', ua.Variant(True, ua.VariantType.Boolean), 'BadTypeMismatch'),
    ('Belts/main/ActualSpeed', ua.Variant(0.1, ua.VariantType.Double), 'BadNotWritable'),
    ('Step', ua.Variant(7, ua.VariantType.UInt64), 'BadNotWritable'),
])
def test_bad_writes_are_refused_counted_and_not_applied(secure_rig, client_cert, path, value,
                                                        status):
    rig = secure_rig
    twin = rig.built.twin
    rejected = twin.commands.rejected_total
    target = float(twin.actuation.belt_target[0])

    async def write() -> Tuple[str, Any]:
        client = await connect(rig.server.url, encrypt=client_cert, user=USER,
                               password=PASSWORD)
        try:
            idx = await client.get_namespace_index(NAMESPACE)
            node = var(client, idx, path)
            try:
                await node.write_value(value)
            except UaStatusCodeError as exc:
                name = type(exc).__name__
            else:
                name = 'Good'
            await call_step(client, idx, 1)
            return name, await var(client, idx, 'RejectedWrites').read_value()
        finally:
            await client.disconnect()

    name, shown = asyncio.run(write())
    assert name == status
    assert twin.commands.rejected_total == rejected + 1
    assert shown == rejected + 1
    assert float(twin.actuation.belt_target[0]) == target


def test_step_refused_outside_lockstep_and_out_of_range(fast_rig, secure_rig, client_cert):
    async def fast() -> str:
        client = await connect(fast_rig.server.url)
        try:
            idx = await client.get_namespace_index(NAMESPACE)
            with pytest.raises(UaStatusCodeError) as info:
                await call_step(client, idx, 10)
            return type(info.value).__name__
        finally:
            await client.disconnect()

    steps = fast_rig.built.twin.step_index
    assert asyncio.run(fast()) == 'BadInvalidState'
    assert fast_rig.built.twin.step_index == steps

    async def out_of_range() -> List[str]:
        client = await connect(secure_rig.server.url, encrypt=client_cert, user=USER,
                               password=PASSWORD)
        names = []
        try:
            idx = await client.get_namespace_index(NAMESPACE)
            for n in (ua.Variant(0, ua.VariantType.UInt32),
                      ua.Variant('x', ua.VariantType.String)):
                with pytest.raises(UaStatusCodeError) as info:
                    await call_step(client, idx, n)
                names.append(type(info.value).__name__)
            return names
        finally:
            await client.disconnect()

    steps = secure_rig.built.twin.step_index
    assert asyncio.run(out_of_range()) == ['BadInvalidArgument', 'BadInvalidArgument']
    assert secure_rig.built.twin.step_index == steps


def test_anonymous_and_wrong_password_refused_when_a_user_is_set(secure_rig, client_cert):
    async def attempt(user: str, password: str) -> str:
        try:
            client = await connect(secure_rig.server.url, encrypt=client_cert, user=user,
                                   password=password)
        except Exception as exc:  # the session is refused
            return type(exc).__name__
        await client.disconnect()
        return 'connected'

    assert asyncio.run(attempt('', '')) != 'connected'
    assert asyncio.run(attempt(USER, 'wrong')) == 'BadUserAccessDenied'
    assert asyncio.run(attempt('other', PASSWORD)) == 'BadUserAccessDenied'
    assert asyncio.run(attempt(USER, PASSWORD)) == 'connected'


def test_policy_none_refused_when_basic256sha256_is_required(secure_rig):
    async def attempt() -> str:
        try:
            client = await connect(secure_rig.server.url, user=USER, password=PASSWORD)
        except Exception as exc:
            return type(exc).__name__
        await client.disconnect()
        return 'connected'

    assert asyncio.run(attempt()) != 'connected'

    async def endpoints() -> List[Tuple[str, int]]:
        client = Client(secure_rig.server.url, timeout=60)
        found = await client.connect_and_get_server_endpoints()
        return [(e.SecurityPolicyUri.rsplit('#', 1)[-1], e.SecurityMode) for e in found]

    assert asyncio.run(endpoints()) == [('Basic256Sha256', ua.MessageSecurityMode.SignAndEncrypt)]
    assert secure_rig.built.twin.health.ok


def test_read_only_refuses_writes_and_steps():
    rig = Rig(TimeMode.LOCKSTEP, OpcUaSecurity(policy='None', read_only=True))
    twin = rig.built.twin
    try:
        async def attempt() -> Tuple[str, str, int]:
            client = await connect(rig.server.url)
            try:
                idx = await client.get_namespace_index(NAMESPACE)
                node = var(client, idx, 'Belts/main/SpeedSetpoint')
                access = await node.read_attribute(ua.AttributeIds.UserAccessLevel)
                with pytest.raises(UaStatusCodeError) as write:
                    await node.write_value(ua.Variant(0.1, ua.VariantType.Double))
                with pytest.raises(UaStatusCodeError) as step:
                    await call_step(client, idx, 1)
                return type(write.value).__name__, type(step.value).__name__, \
                    access.Value.Value
            finally:
                await client.disconnect()

        write, step, access = asyncio.run(attempt())
        assert (write, step) == ('BadUserAccessDenied', 'BadUserAccessDenied')
        assert access == ua.AccessLevel.CurrentRead.mask
        assert twin.commands.rejected['read_only'] == 2
        assert twin.step_index == 0 and len(twin.commands.drain(1)) == 0
    finally:
        rig.close()


def test_certificate_is_made_once_and_reused(tmp_path):
    cert, key = server_certificate(str(tmp_path), '127.0.0.1')
    made = cert.read_bytes()
    assert (tmp_path.stat().st_mode & 0o777) == 0o700
    assert (key.stat().st_mode & 0o777) == 0o600
    assert server_certificate(str(tmp_path), '127.0.0.1')[0].read_bytes() == made
    assert server_certificate(str(tmp_path), '127.0.0.2')[0].read_bytes() != made  # new host
    made = cert.read_bytes()
    key.write_bytes(b'not a key')  # broken: made again
    cert2, _ = server_certificate(str(tmp_path), '127.0.0.1')
    assert cert2.read_bytes() != made


# --- start, stop and failures ---------------------------------------------------------------

class _FailingState:
    """A state whose refresh fails once asked to (a bug in the server thread's work)."""

    def __init__(self) -> None:
        self.cell = load_cell()
        self.real = PlcState(self.cell, mode='fast')
        self.tags = self.real.tags
        self.fail = threading.Event()

    def refresh(self) -> Any:
        if self.fail.is_set():
            raise RuntimeError('refresh broke')
        return self.real.refresh()


def test_a_port_in_use_raises_naming_it_and_a_thread_failure_is_reported_once():
    cell = load_cell()
    writer = PlcWriter(build_twin(cell, seed=1).twin.commands, sender='opcua')
    handshake = StepHandshake(lambda n: None, mode_is_lockstep=False)
    health = Health(printer=lambda text: None)
    state = _FailingState()
    server = OpcUaServer(state, writer, handshake, host='127.0.0.1', port=0, health=health,
                         security=OpcUaSecurity(policy='None'))
    server.start()
    try:
        taken = server.port
        again = OpcUaServer(state, writer, handshake, host='127.0.0.1', port=taken,
                            health=health, security=OpcUaSecurity(policy='None'))
        with pytest.raises(PlcServerError, match=f'127.0.0.1:{taken}'):
            again.start()
        assert not again.running
        assert health.ok
        state.fail.set()
        assert health.event.wait(BUDGET)
        wait_for(lambda: not server.running, 'the failed server thread ends')
        assert [f.name for f in health.failures] == [HEALTH_NAME]
        assert 'refresh broke' in health.failures[0].error
    finally:
        server.stop()
    assert len(health.failures) == 1


def test_bad_arguments_are_refused_naming_them():
    cell = load_cell()
    writer = PlcWriter(build_twin(cell, seed=1).twin.commands, sender='opcua')
    state = PlcState(cell, mode='fast')
    handshake = StepHandshake(lambda n: None, mode_is_lockstep=False)
    with pytest.raises(ValueError, match='update_period 0'):
        OpcUaServer(state, writer, handshake, host='127.0.0.1', port=0, health=Health(),
                    update_period=0)
    with pytest.raises(ValueError, match='read-only PlcWriter'):
        OpcUaServer(state, writer, handshake, host='127.0.0.1', port=0, health=Health(),
                    security=OpcUaSecurity(policy='None', read_only=True))
    with pytest.raises(ValueError, match="policy 'Basic128'"):
        OpcUaSecurity(policy='Basic128')
    with pytest.raises(ValueError, match='needs a password'):
        OpcUaSecurity(user='plc')
    assert len([t for t in tag_map(cell).tags if t.opcua]) == len(
        [t for t in state.tags if t.opcua])
