"""The PLC servers of a whole twin: what OPC UA and Modbus clients see equals what ROS shows.

A :class:`~conveyor_twin.testing.LockstepTwin` of the default cell with both servers (real
asyncua and pymodbus clients on 127.0.0.1): edges counted through each protocol at a 10 ms
poll equal ``light_barrier_edges``; writes show in ``belt_states``; bad writes are refused,
counted and applied nowhere; the lockstep handshake of each protocol gives the edge times of
the harness's own stepping; a client that stalls or vanishes never stalls the twin; a server
that dies is a background failure of the twin.
"""

import math
from pathlib import Path
import socket
import time

from diagnostic_msgs.msg import DiagnosticStatus
import pytest

from conveyor_twin.health import BackgroundFailure
from conveyor_twin.plc.options import PlcOptions
from conveyor_twin.plc.tags import tag_map
from conveyor_twin.testing import LockstepTwin
from test.plc.plc_clients import Modbus, OpcUa

pytestmark = pytest.mark.ros

SEED = 5
#: Parts placed just before ``lb_infeed`` (x = 2.0 m) so that edges come within a second.
SPAWN_X = (1.80, 1.85, 1.90, 1.70, 1.75)
SPAWN_Y = (-0.15, 0.0, 0.15, 0.08, -0.08)
PLC = PlcOptions(security='None')
#: Bound on how long an OPC UA variable may take to show a step [s] (the server updates its
#: variables every 20 ms; generous for a loaded machine).
SHOW_TIMEOUT = 30.0


def _until(read, ok, what: str):
    """Return ``read()`` once ``ok`` holds for it; fail after :data:`SHOW_TIMEOUT`."""
    deadline = time.monotonic() + SHOW_TIMEOUT
    while True:
        value = read()
        if ok(value):
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f'{what}: still {value!r} after {SHOW_TIMEOUT} s')
        time.sleep(0.005)


def _at_step(opcua, step: int) -> None:
    """Wait until the OPC UA variables show ``step`` (one update writes them all)."""
    _until(lambda: opcua.read(['Step'])[0], lambda v: v == step, 'OPC UA Step')


def _spawn(twin: LockstepTwin) -> None:
    twin.spawn('spacer', SPAWN_X, SPAWN_Y)


@pytest.fixture(scope='module')
def served():
    """A lockstep twin serving OPC UA and Modbus, with a client of each."""
    with LockstepTwin(seed=SEED, opcua='0', modbus='0', plc=PLC) as twin:
        opcua = OpcUa(twin.plc.opcua_url)
        modbus = Modbus(twin.plc.modbus_port, tag_map(twin.cell))
        try:
            yield twin, opcua, modbus
        finally:
            opcua.close()
            modbus.close()


def test_edges_through_opcua_and_modbus_equal_the_ros_edges(served):
    twin, opcua, modbus = served
    names = [b.name for b in twin.cell.light_barriers]
    start = twin.step_index
    before = {n: (sum(e.blocked for e in twin.edges(name=n)),
                  sum(not e.blocked for e in twin.edges(name=n))) for n in names}
    _at_step(opcua, twin.step_index)
    first_opcua = _opcua_counts(opcua, names)
    first_modbus = _modbus_counts(modbus, names)
    _spawn(twin)
    for _ in range(150):  # 1.5 s, polled every 10 ms of simulation time
        twin.step(10)
        _at_step(opcua, twin.step_index)
        opcua_counts = _opcua_counts(opcua, names)
        modbus_counts = _modbus_counts(modbus, names)
    ros = {n: (sum(e.blocked for e in twin.edges(name=n, since_step=start + 1)),
               sum(not e.blocked for e in twin.edges(name=n, since_step=start + 1)))
           for n in names}
    assert ros['lb_infeed'][0] >= len(SPAWN_X), ros
    for n in names:
        assert _diff(opcua_counts[n], first_opcua[n]) == ros[n], (n, before)
        assert _diff(modbus_counts[n], first_modbus[n]) == ros[n], n
    # the blocked flags and the last edge time agree too
    last = [e for e in twin.edges(name='lb_infeed') if e.blocked][-1]
    blocked, rising_s = opcua.read(['Barriers/lb_infeed/Blocked',
                                    'Barriers/lb_infeed/LastRisingTime'])
    assert blocked == twin.barrier('lb_infeed').blocked
    assert rising_s == pytest.approx(last.time_ns * 1e-9, abs=1e-9)
    inputs = modbus.inputs()
    assert inputs['Barriers/lb_infeed/Blocked'] == twin.barrier('lb_infeed').blocked
    assert inputs['Barriers/lb_infeed/LastRisingTime'] == round(last.time_ns * 1e-6)


def _diff(now, then):
    return tuple((a - b) % 2**32 for a, b in zip(now, then))


def _opcua_counts(opcua, names):
    values = opcua.read([f'Barriers/{n}/{k}' for n in names
                         for k in ('RisingEdges', 'FallingEdges')])
    return {n: (int(values[2 * i]), int(values[2 * i + 1])) for i, n in enumerate(names)}


def _modbus_counts(modbus, names):
    inputs = modbus.inputs()
    return {n: (int(inputs[f'Barriers/{n}/RisingEdges']),
                int(inputs[f'Barriers/{n}/FallingEdges'])) for n in names}


def test_a_written_setpoint_shows_in_belt_states(served):
    twin, opcua, modbus = served
    opcua.write_double('Belts/main/SpeedSetpoint', 1.25)
    twin.step(2)
    assert twin.belt('main').commanded_speed == 1.25
    _until(lambda: opcua.read(['Belts/main/SpeedSetpoint'])[0], lambda v: v == 1.25,
           'OPC UA SpeedSetpoint')
    reply = modbus.write(modbus.tags.by_path('Belts/main/SpeedSetpoint'), 0.75)
    assert not reply.isError(), reply
    twin.step(2)
    assert twin.belt('main').commanded_speed == 0.75  # exact in float32 too
    reply = modbus.write(modbus.tags.by_path('Actuators/pusher/Target'), 0.25)
    assert not reply.isError(), reply
    twin.step(2)
    assert twin.actuator('pusher').commanded_position == 0.25


def test_a_bad_write_is_refused_counted_and_applied_nowhere(served):
    from asyncua.ua.uaerrors import BadOutOfRange
    twin, opcua, modbus = served
    twin.set_belt('main', 0.5)
    twin.step(2)
    rejected = _rejected(twin)
    with pytest.raises(BadOutOfRange):
        opcua.write_double('Belts/main/SpeedSetpoint', 5.0)
    setpoint = modbus.tags.by_path('Belts/main/SpeedSetpoint')
    for value in (-9.0, math.nan):
        reply = modbus.write(setpoint, value)
        assert reply.isError() and reply.exception_code == 3, reply
    twin.step(5)
    assert _rejected(twin) == rejected + 3
    assert {s.commanded for s in twin.belt_history('main')[-5:]} == {0.5}
    _until(lambda: opcua.read(['RejectedWrites'])[0], lambda v: v >= 3, 'OPC UA RejectedWrites')


def _rejected(twin) -> int:
    """``rejected_commands`` of the twin's latest diagnostics."""
    msg = twin.composed.coordinator.diagnostics(twin.time_ns)
    values = {kv.key: kv.value for s in msg.status for kv in s.values}
    return int(values['rejected_commands'])


def test_a_stalled_or_vanished_client_never_stalls_the_twin(served):
    twin, opcua, modbus = served
    stalled = []
    for port in (twin.plc.modbus_port, twin.plc.opcua_port):
        s = socket.create_connection(('127.0.0.1', port), timeout=10)
        s.sendall(b'\x00\x01\x00')  # half a request, then silence
        stalled.append(s)
    gone = socket.create_connection(('127.0.0.1', twin.plc.modbus_port), timeout=10)
    gone.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b'\x01\x00\x00\x00\x00\x00\x00\x00')
    gone.close()  # reset
    start = twin.step_index
    assert twin.step(500) == start + 500
    assert modbus.inputs()['Step'] == start + 500
    _at_step(opcua, start + 500)
    for s in stalled:
        s.close()


def test_the_lockstep_handshake_gives_the_harness_edge_times():
    with LockstepTwin(seed=SEED) as reference:
        _spawn(reference)
        reference.step(2001)
        expected = [(e.name, e.blocked, e.time_ns) for e in reference.edges()]
    assert len(expected) >= len(SPAWN_X)
    with LockstepTwin(seed=SEED, opcua='0', modbus='0', plc=PLC) as twin:
        _spawn(twin)
        opcua = OpcUa(twin.plc.opcua_url)
        modbus = Modbus(twin.plc.modbus_port, tag_map(twin.cell))
        try:
            for k in range(100):  # OPC UA: Step(10), 100 times
                assert opcua.step(10) == 10 * (k + 1)
            tick = modbus.tags.by_path('Lockstep/Tick')
            for k in range(1, 101):  # Modbus: Tick + 1 (10 steps each), 100 times
                assert not modbus.write(tick, k).isError()
                inputs = modbus.inputs()
                assert inputs['Lockstep/DoneTick'] == k and inputs['Lockstep/Done']
            assert inputs['Step'] == 2000
        finally:
            opcua.close()
            modbus.close()
        twin.step(1)  # the harness's step waits for every stream and edge before it
        got = [(e.name, e.blocked, e.time_ns) for e in twin.edges()]
    assert got == expected


def test_a_server_that_dies_is_a_background_failure():
    with LockstepTwin(seed=SEED, modbus='0', plc=PLC) as twin:
        twin.step(10)

        def broken():
            raise RuntimeError('injected failure of the PLC state')
        twin.plc.state.refresh = broken
        client = Modbus(twin.plc.modbus_port, tag_map(twin.cell))
        try:
            with pytest.raises(Exception):
                client.inputs()
        finally:
            client.close()
        with pytest.raises(BackgroundFailure, match='Modbus server'):  # once it is reported
            twin.wait_until(lambda: False, timeout=60)
        with pytest.raises(BackgroundFailure, match='Modbus server'):
            twin.step(10)
        assert twin.composed.coordinator.summary()['failures'][0]['name'] == 'Modbus server'
        statuses = twin.composed.coordinator.diagnostics(twin.time_ns).status
        assert any(s.level == DiagnosticStatus.ERROR and 'Modbus server' in s.message
                   for s in statuses)


@pytest.mark.parametrize('kwargs, message', [
    ({'opcua': 'host:port'}, "opcua 'host:port': port 'port'"),
    ({'modbus': '0', 'layout': 'split'}, 'composed layout'),
])
def test_bad_plc_arguments_of_the_harness_are_clear_errors(kwargs, message):
    with pytest.raises(ValueError, match=message):
        LockstepTwin(**kwargs)


def test_writes_reach_the_twin_after_a_reset_to_another_cell_file():
    from conveyor_twin.cell import loader
    cell_file = Path(loader.__file__).with_name('default_cell.yaml')
    with LockstepTwin(seed=SEED, modbus='0', plc=PLC) as twin:
        client = Modbus(twin.plc.modbus_port, tag_map(twin.cell))
        try:
            twin.step(5)
            twin.reset(cell_file=cell_file)  # a new cell object: a new command book
            setpoint = client.tags.by_path('Belts/main/SpeedSetpoint')
            assert not client.write(setpoint, 1.5).isError()
            twin.step(2)
            assert twin.belt('main').commanded_speed == 1.5
        finally:
            client.close()
