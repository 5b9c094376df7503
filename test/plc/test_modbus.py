"""The Modbus TCP server against a real pymodbus client on loopback: reads, writes, lockstep."""

from dataclasses import replace
import math
import socket
import struct
import threading
import time

from pymodbus.client import ModbusTcpClient
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
from conveyor_twin.plc.modbus_registers import LayoutError, ModbusTables, Table
from conveyor_twin.plc.modbus_server import MODBUS_SERVER, ModbusServer
from conveyor_twin.plc.state import PlcState
from conveyor_twin.plc.tags import modbus_value, tag_map
from conveyor_twin.plc.writes import PlcWriter
from conveyor_twin.wire.decoders import decode_light_barrier_edge, decode_light_barrier_states

#: A PLC's poll period [s].
POLL = 0.01
#: Generous budget for anything that waits on a condition [s].
BUDGET = 120.0
ILLEGAL_ADDRESS, ILLEGAL_VALUE, DEVICE_FAILURE = 2, 3, 4


class EdgeSink:
    """A frame sink keeping what the frames said about the light barriers."""

    def __init__(self, cell) -> None:
        self.index = {b.name: i for i, b in enumerate(cell.light_barriers)}
        n = len(self.index)
        self.rising, self.falling = [0] * n, [0] * n
        self.last_rising, self.last_falling = [None] * n, [None] * n
        self.stamps = []
        self.barriers = None

    def on_frame(self, frame) -> None:
        for stamp, data in frame.edges:
            edge = decode_light_barrier_edge(data)
            i = self.index[edge.name]
            self.stamps.append((i, edge.blocked, stamp))
            if edge.blocked:
                self.rising[i] += 1
                self.last_rising[i] = stamp
            else:
                self.falling[i] += 1
                self.last_falling[i] = stamp
        self.barriers = frame.light_barriers

    def blocked(self):
        return [bool(b) for b in decode_light_barrier_states(self.barriers)[4]]


class Rig:
    """A core twin (no ROS) with its PLC state, a Modbus server on a free port and a client."""

    def __init__(self, mode: str, *, max_steps=None, read_only: bool = False, seed: int = 1,
                 health=None, step=None) -> None:
        self.cell = load_cell()
        self.built = build_twin(self.cell, seed=seed)
        self.twin = self.built.twin
        if health is not None:
            self.twin.health = health
        output = TwinOutput([CoordinatorOutput(self.twin), MicroOutput(self.built.micro),
                             MacroOutput(self.built.macro)])
        self.twin.step_listeners.append(output.on_step)
        self.runner = Runner(self.twin, TimeMode(mode), max_steps=max_steps)
        self.handshake = StepHandshake(step or self.runner.step,
                                       mode_is_lockstep=mode == 'lockstep')
        self.state = PlcState(self.cell, mode=mode, handshake=self.handshake,
                              rejected=lambda: self.twin.commands.rejected_total)
        self.edges = EdgeSink(self.cell)
        output.subscribe(self.state)
        output.subscribe(self.edges)
        self.map = self.state.map
        self.server = ModbusServer(self.state, PlcWriter(self.twin.commands, sender='modbus',
                                                         read_only=read_only),
                                   self.handshake, port=0, health=self.twin.health,
                                   read_only=read_only)
        self.server.start()
        self.client = ModbusTcpClient('127.0.0.1', port=self.server.port, timeout=BUDGET,
                                      retries=0)
        assert self.client.connect()

    def address(self, path: str) -> int:
        return self.map.by_path(path).modbus_address

    def inputs(self) -> dict:
        """Every input register and discrete input, decoded by tag path."""
        size = self.map.modbus_size('input')
        regs = ok(self.client.read_input_registers(0, count=size)).registers
        bits = ok(self.client.read_discrete_inputs(0, count=self.map.modbus_size('discrete')))
        out = {t.path: modbus_value(t, regs[t.modbus_address:t.modbus_address + t.modbus_words])
               for t in self.map.modbus('input')}
        out.update({t.path: bits.bits[t.modbus_address] for t in self.map.modbus('discrete')})
        return out

    def write_float(self, path: str, value: float):
        return self.client.write_registers(self.address(path), float_words(value))

    def close(self) -> None:
        self.client.close()
        self.server.stop()
        self.runner.stop()


@pytest.fixture
def rigs():
    made = []

    def make(mode: str, **kwargs) -> Rig:
        made.append(Rig(mode, **kwargs))
        return made[-1]
    yield make
    for rig in made:
        rig.close()
        rig.twin.health.raise_if_failed()


def ok(response):
    assert not response.isError(), response
    return response


def float_words(value: float):
    return list(struct.unpack('>HH', struct.pack('>f', value)))


def ms(time_ns) -> int:
    return int(round(time_ns / 1e6)) if time_ns is not None else 0


def barrier_registers(rig: Rig, values: dict, i: int):
    name = f'Barriers/{rig.cell.light_barriers[i].name}/'
    return [values[name + key] for key in ('RisingEdges', 'FallingEdges', 'LastRisingTime',
                                           'LastFallingTime', 'Blocked')]


def test_every_edge_of_a_fast_run_is_counted_at_a_10_ms_poll(rigs):
    rig = rigs('fast', max_steps=10_000)
    rig.runner.start()
    polls = []
    deadline = time.monotonic() + BUDGET
    while rig.runner.running:
        polls.append(rig.inputs())
        assert time.monotonic() < deadline, 'the run did not end'
        time.sleep(POLL)  # the PLC's cycle
    final = rig.inputs()
    assert final['Step'] == 10_000 and final['SimulationTime'] == 10_000  # ms
    assert len(polls) > 1, 'no poll during the run'
    blocked = rig.edges.blocked()
    assert sum(rig.edges.rising) > 10
    for i in range(len(rig.cell.light_barriers)):
        assert barrier_registers(rig, final, i) == [
            rig.edges.rising[i], rig.edges.falling[i], ms(rig.edges.last_rising[i]),
            ms(rig.edges.last_falling[i]), blocked[i]]
        counts = [barrier_registers(rig, p, i)[:2] for p in polls + [final]]
        assert counts == sorted(counts), 'a counter went back'


def test_a_written_setpoint_reaches_the_belt_and_reads_back(rigs):
    rig = rigs('lockstep')
    book = rig.twin.commands
    ok(rig.write_float('Belts/main/SpeedSetpoint', 0.1))
    # one request may write several values (all validated first)
    target = rig.address('Actuators/pusher/Target')
    assert target == rig.address('Belts/main/SpeedSetpoint') + 2
    ok(rig.client.write_registers(target, float_words(0.25) + float_words(0.008)))
    rig.runner.step(2)
    # a float32 means the shortest decimal it shows: 0.1, and the stopper's 0.008 m (its
    # range's end, whose nearest float32 is 0.00800000038) is accepted
    assert rig.twin.actuation.belt_target[0] == 0.1
    assert book.rejected_total == 0
    view = rig.state.refresh()
    assert view.value(rig.map.by_path('Actuators/stopper/Target')) == 0.008
    assert view.value(rig.map.by_path('Actuators/pusher/Target')) == 0.25
    held = ok(rig.client.read_holding_registers(0, count=rig.map.modbus_size('holding')))
    tag = rig.map.by_path('Belts/main/SpeedSetpoint')
    assert held.registers[tag.modbus_address:][:2] == float_words(0.1)
    assert held.registers[rig.address('Lockstep/TickSteps')] == 10


@pytest.mark.parametrize('request_, code', [
    (lambda r: r.write_float('Belts/main/SpeedSetpoint', 5.0), ILLEGAL_VALUE),
    (lambda r: r.write_float('Belts/main/SpeedSetpoint', math.nan), ILLEGAL_VALUE),
    (lambda r: r.write_float('Belts/main/SpeedSetpoint', -math.inf), ILLEGAL_VALUE),
    (lambda r: r.write_float('Actuators/pusher/Target', 0.6), ILLEGAL_VALUE),
    # half a float: one register of it (function 6 or 16), or straddling two values
    (lambda r: r.client.write_register(r.address('Belts/main/SpeedSetpoint'), 0x3DCC),
     ILLEGAL_VALUE),
    (lambda r: r.client.write_registers(r.address('Belts/main/SpeedSetpoint') + 1, [0]),
     ILLEGAL_VALUE),
    (lambda r: r.client.write_registers(r.address('Belts/main/SpeedSetpoint') + 1, [0, 0]),
     ILLEGAL_VALUE),
    # several values, one bad: none applied
    (lambda r: r.client.write_registers(r.address('Belts/main/SpeedSetpoint'),
                                        float_words(0.1) + float_words(9.0)), ILLEGAL_VALUE),
    (lambda r: r.client.write_registers(r.map.modbus_size('holding'), [0, 0]),
     ILLEGAL_ADDRESS),
    (lambda r: r.client.write_coil(0, True), ILLEGAL_ADDRESS),
    (lambda r: r.client.write_register(r.address('Lockstep/TickSteps'), 0), ILLEGAL_VALUE),
    (lambda r: r.client.write_register(r.address('Lockstep/Tick'), 2), ILLEGAL_VALUE),
    # the whole holding table in one request, with a wrong tick: no value applied either
    (lambda r: r.client.write_registers(0, [5, 20] + float_words(0.1)), ILLEGAL_VALUE),
])
def test_a_bad_write_is_answered_with_its_exception_and_changes_nothing(rigs, request_, code):
    rig = rigs('lockstep')
    before = rig.state.refresh()
    response = request_(rig)
    assert response.isError() and response.exception_code == code
    rig.runner.step(2)
    after = rig.state.refresh()
    for tag in rig.map.modbus('holding'):
        assert after.value(tag) == before.value(tag), tag.path
    assert rig.twin.commands.rejected_total == 1
    assert rig.inputs()['RejectedWrites'] == 1
    assert rig.server.counters()['rejected'] == 1


def test_one_request_sets_the_values_then_steps_its_tick(rigs):
    rig = rigs('lockstep')
    assert rig.address('Lockstep/Tick') == 0 and rig.address('Belts/main/SpeedSetpoint') == 2
    ok(rig.client.write_registers(0, [1, 20] + float_words(0.3)))
    values = rig.inputs()
    assert (values['Step'], values['Lockstep/DoneTick']) == (20, 1)
    assert rig.twin.actuation.belt_target[0] == 0.3 and values['RejectedWrites'] == 0


def test_reads_outside_the_map_and_other_units_are_refused(rigs):
    rig = rigs('lockstep')
    c, m = rig.client, rig.map
    for response in (c.read_input_registers(m.modbus_size('input'), count=1),
                     c.read_input_registers(m.modbus_size('input') - 1, count=2),
                     c.read_holding_registers(m.modbus_size('holding'), count=1),
                     c.read_discrete_inputs(m.modbus_size('discrete'), count=1),
                     c.read_coils(0, count=1)):
        assert response.isError() and response.exception_code == ILLEGAL_ADDRESS, response
    other = c.read_input_registers(0, count=1, device_id=7)
    assert other.isError() and other.exception_code == 0x0B
    assert ok(c.read_input_registers(1, count=1)).registers == [0]  # half a value: allowed


def test_read_only_refuses_every_write(rigs):
    rig = rigs('lockstep', read_only=True)
    for response in (rig.write_float('Belts/main/SpeedSetpoint', 0.5),
                     rig.client.write_register(rig.address('Lockstep/Tick'), 1)):
        assert response.isError() and response.exception_code == ILLEGAL_VALUE
    assert rig.twin.commands.rejected_total == 2 and rig.runner.steps_done == 0


def test_lockstep_ticks_step_exactly_tick_steps_as_the_same_seed_stepped_directly(rigs):
    rig = rigs('lockstep')
    c = rig.client
    tick, steps = rig.address('Lockstep/Tick'), rig.address('Lockstep/TickSteps')
    ok(c.write_register(steps, 500))
    for k in range(1, 13):
        ok(c.write_register(tick, k))
        values = rig.inputs()
        assert (values['Lockstep/DoneTick'], values['Lockstep/Done'], values['Step']) == \
            (k, True, 500 * k)
    ok(c.write_register(tick, 12))  # the same tick again (a retry): no step
    assert rig.inputs()['Step'] == 6000 and rig.runner.steps_done == 6000
    refused = c.write_register(tick, 14)
    assert refused.isError() and refused.exception_code == ILLEGAL_VALUE
    ok(c.write_registers(tick, [13, 2]))  # Tick and TickSteps in one request: steps first
    assert rig.inputs()['Step'] == 6002
    assert rig.inputs()['RejectedWrites'] == 1

    direct = build_twin(load_cell(), seed=1)
    output = TwinOutput([CoordinatorOutput(direct.twin), MicroOutput(direct.micro),
                         MacroOutput(direct.macro)])
    direct.twin.step_listeners.append(output.on_step)
    edges = EdgeSink(direct.cell)
    output.subscribe(edges)
    direct.twin.step(6002)
    assert rig.edges.stamps == edges.stamps and len(edges.stamps) > 10
    values = rig.inputs()
    for i in range(len(rig.cell.light_barriers)):
        assert barrier_registers(rig, values, i) == [
            edges.rising[i], edges.falling[i], ms(edges.last_rising[i]),
            ms(edges.last_falling[i]), edges.blocked()[i]]


def test_done_is_0_while_a_tick_steps_and_other_clients_are_served(rigs):
    release = threading.Event()
    holder = {}

    def held_step(n: int) -> None:  # the tick's steps wait until the test lets them run
        assert release.wait(BUDGET)
        holder['rig'].runner.step(n)
    rig = holder['rig'] = rigs('lockstep', step=held_step)
    other = ModbusTcpClient('127.0.0.1', port=rig.server.port, timeout=BUDGET, retries=0)
    assert other.connect()
    done = {}
    ticking = threading.Thread(target=lambda: done.setdefault(
        'reply', other.write_register(rig.address('Lockstep/Tick'), 1)))
    ticking.start()
    try:
        deadline = time.monotonic() + BUDGET
        while rig.inputs()['Lockstep/Done']:
            assert time.monotonic() < deadline, 'the tick never started'
        values = rig.inputs()
        assert (values['Lockstep/Done'], values['Lockstep/DoneTick'], values['Step']) == \
            (False, 0, 0)
    finally:
        release.set()
        ticking.join(BUDGET)
        other.close()
    ok(done['reply'])
    values = rig.inputs()
    assert (values['Lockstep/Done'], values['Lockstep/DoneTick'], values['Step']) == (True, 1, 10)


def test_a_tick_outside_lockstep_is_refused_and_counted(rigs):
    rig = rigs('fast')
    response = rig.client.write_register(rig.address('Lockstep/Tick'), 1)
    assert response.isError() and response.exception_code == ILLEGAL_VALUE
    assert rig.runner.steps_done == 0 and rig.inputs()['RejectedWrites'] == 1


def test_stalled_and_garbage_clients_do_not_hold_the_run(rigs):
    rig = rigs('fast', max_steps=5000)
    port = rig.server.port
    idle = socket.create_connection(('127.0.0.1', port))
    garbage = socket.create_connection(('127.0.0.1', port))
    garbage.sendall(bytes(range(256)) * 4)
    half = socket.create_connection(('127.0.0.1', port))
    half.sendall(b'\x00\x01\x00\x00\x00\x06')  # a request's header, its body never sent
    try:
        rig.runner.start()
        deadline = time.monotonic() + BUDGET
        while rig.runner.running:
            assert time.monotonic() < deadline, 'the run did not end'
            time.sleep(POLL)  # the PLC's cycle
        assert rig.runner.steps_done == 5000
        assert rig.inputs()['Step'] == 5000  # a client behaving is still served
        rig.server.stop()  # with every client still connected
        assert not rig.server.running
        with pytest.raises(ConnectionRefusedError):
            socket.create_connection(('127.0.0.1', port)).close()
    finally:
        for s in (idle, garbage, half):
            s.close()


def test_a_failing_refresh_is_answered_04_and_reported_once(rigs):
    printed = []
    rig = rigs('lockstep', health=Health(printer=printed.append))

    def broken():
        raise RuntimeError('decoder broke')
    rig.state.refresh = broken
    for _ in range(2):
        response = rig.client.read_input_registers(0, count=2)
        assert response.isError() and response.exception_code == DEVICE_FAILURE
    failures = rig.twin.health.failures
    assert [f.name for f in failures] == [MODBUS_SERVER] and 'decoder broke' in failures[0].error
    assert len(printed) == 1
    rig.twin.health = Health()  # the fixture checks the health of the others


def test_start_names_the_address_it_cannot_bind_and_leaves_nothing_running():
    rig_cell = load_cell()
    built = build_twin(rig_cell, seed=1)
    state = PlcState(rig_cell, mode='lockstep')
    handshake = StepHandshake(built.twin.step, mode_is_lockstep=True)
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        server = ModbusServer(state, PlcWriter(built.twin.commands, sender='modbus'),
                              handshake, port=port, health=built.twin.health)
        with pytest.raises(PlcServerError, match=f'127.0.0.1:{port}'):
            server.start()
        assert not server.running and not server._thread.is_alive()
    assert built.twin.health.ok
    with pytest.raises(PlcServerError, match='unit id 300'):
        ModbusServer(state, PlcWriter(built.twin.commands, sender='modbus'), handshake,
                     health=built.twin.health, unit_id=300)


def test_the_tables_know_each_address_and_whole_values():
    tables = ModbusTables(tag_map(load_cell()))
    holding = tables['holding']
    setpoint = holding.owners[2][0]
    assert setpoint.path == 'Belts/main/SpeedSetpoint' and holding.owners[3] == (setpoint, 1)
    assert holding.whole_tags(0, 4)[2] is setpoint and len(holding.whole_tags(0, 4)) == 3
    assert holding.whole_tags(3, 2) is None and holding.whole_tags(2, 1) is None
    assert not holding.covers(holding.size - 1, 2) and tables['coil'].size == 0
    clash = replace(setpoint, path='Other', modbus_address=3)
    with pytest.raises(LayoutError, match="'Belts/main/SpeedSetpoint' and 'Other' share "
                                          'address 3'):
        Table('holding', [setpoint, clash])
