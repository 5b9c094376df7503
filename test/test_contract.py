"""The contract table against msg_defs/, the schemas the recorder writes and the design's list."""

import pathlib

import pytest

from conveyor_twin import contract
from conveyor_twin.contract import Kind, Producer, Rate, Shape, Stamp
from conveyor_twin.output.frame import Frame, FRAME_STREAMS
from conveyor_twin.wire import schemas

ROOT = pathlib.Path(__file__).resolve().parents[1]
MSG_DEFS = ROOT / 'msg_defs'
# the ROS interface as the design lists it (name, type, direction)
INTERFACE = {
    'parts': ('PartStates', Kind.STREAM), 'density': ('DensityGrid', Kind.STREAM),
    'light_barriers': ('LightBarrierStates', Kind.STREAM),
    'light_barrier_edges': ('LightBarrierEdge', Kind.STREAM),
    'belt_states': ('BeltStates', Kind.STREAM), 'actuator_states': ('ActuatorStates', Kind.STREAM),
    '/clock': ('Clock', Kind.STREAM), 'diagnostics': ('DiagnosticArray', Kind.STREAM),
    'belt_command': ('BeltCommand', Kind.COMMAND),
    'actuator_command': ('ActuatorCommand', Kind.COMMAND),
    'step': ('Step', Kind.SERVICE), 'reset': ('Reset', Kind.SERVICE),
    'spawn_parts': ('SpawnParts', Kind.SERVICE),
}


def test_every_interface_entry_is_in_the_table_once():
    entries = contract.STREAMS + contract.COMMANDS + contract.SERVICES
    assert len({t.name for t in entries}) == len(entries)
    # beyond the design's list: markers (viewer data, not recorded by default), the answers to
    # commands (command_status) and the faults interface (faults, inject_fault, clear_fault)
    assert set(contract.CONTRACT) == set(INTERFACE) | {'markers', 'command_status', 'faults',
                                                       'inject_fault', 'clear_fault'}
    for name, (short, kind) in INTERFACE.items():
        topic = contract.CONTRACT[name]
        assert topic.type_name.split('/')[-1] == short and topic.kind is kind, name
    assert not contract.MARKERS.default and not contract.COMMAND_STATUS.default and all(
        t.default for t in contract.STREAMS + contract.COMMANDS if t is not contract.MARKERS)


@pytest.mark.parametrize('topic', contract.STREAMS + contract.COMMANDS + contract.REPLIES
                         + tuple(contract.PLANT.values()), ids=lambda t: t.name)
def test_every_topic_type_has_a_schema_with_the_fields_of_msg_defs(topic):
    assert topic.type_name in schemas.SCHEMAS
    package, _, name = topic.type_name.split('/')
    if package != 'conveyor_twin_msgs':
        return
    path = MSG_DEFS / 'msg' / f'{name}.msg'
    expected = [(f.name, f.base, f.array)
                for f in schemas.parse_fields(topic.type_name, path.read_text())]
    got = [(f.name, f.base, f.array)
           for f in schemas.parse_fields(topic.type_name, schemas.MSG_TEXTS[topic.type_name])]
    assert got == expected
    if topic.stamp is Stamp.HEADER:  # the stamp is the first 8 bytes of the payload
        assert expected[0][:2] == ('header', 'std_msgs/msg/Header')


def test_every_interface_file_is_in_the_table():
    in_table = {t.type_name for t in contract.CONTRACT.values()}
    in_table |= {t.type_name for t in contract.PLANT.values()}
    for path in sorted((MSG_DEFS / 'msg').glob('*.msg')):
        assert f'conveyor_twin_msgs/msg/{path.stem}' in in_table, path.name
    for path in sorted((MSG_DEFS / 'srv').glob('*.srv')):
        assert f'conveyor_twin_msgs/srv/{path.stem}' in in_table, path.name
    for service in contract.SERVICES:
        assert (MSG_DEFS / 'srv' / (service.type_name.split('/')[-1] + '.srv')).is_file()


def test_qos_rates_stamps_and_producers():
    every_step = ('parts', 'density', 'light_barriers', 'belt_states', 'actuator_states')
    for name in every_step:
        topic = contract.TOPICS[name]
        assert topic.rate is Rate.STEP and topic.stamp is Stamp.HEADER
        assert (topic.qos.reliability, topic.qos.history, topic.qos.depth) == \
            ('reliable', 'keep_last', 100)
    edges = contract.LIGHT_BARRIER_EDGES
    assert edges.qos.reliability == 'reliable' and edges.qos.depth > 100
    clock = contract.CLOCK
    assert (clock.qos.reliability, clock.qos.depth, clock.stamp) == ('best_effort', 1,
                                                                     Stamp.CLOCK)
    assert contract.DIAGNOSTICS.rate is Rate.DIAGNOSTICS
    assert all(t.stamp is Stamp.NONE for t in contract.COMMANDS)
    # every stream but markers is in the frame, and each stage's part is what it produces
    assert set(FRAME_STREAMS) == set(contract.STREAMS) - {contract.MARKERS}
    assert contract.produced_by(Producer.MACRO) == (contract.DENSITY,)
    assert set(contract.produced_by(Producer.MICRO)) == {
        contract.PARTS, contract.LIGHT_BARRIERS, contract.LIGHT_BARRIER_EDGES, contract.MARKERS}


def test_the_frame_table_places_every_stream_of_a_step_once():
    slots = contract.FRAME
    assert len({s.topic for s in slots}) == len({s.attribute for s in slots}) == len(slots)
    assert FRAME_STREAMS == tuple(s.topic for s in slots)
    assert all(s.topic.kind is Kind.STREAM and s.attribute in Frame.__slots__ for s in slots)
    # one message or None per step, but a sequence for the edges and the zones' grids
    assert {s.topic: s.empty for s in slots if s.shape is not Shape.ONE} == {
        contract.LIGHT_BARRIER_EDGES: (), contract.DENSITY: ()}
    # the one-message streams come first: sinks that group by shape keep the table's order
    ones = [s.shape is Shape.ONE for s in slots]
    assert ones == sorted(ones, reverse=True)
    frame = Frame()
    assert all(getattr(frame, s.attribute) == s.empty for s in slots)
    assert list(frame.messages()) == []
    # a stream outage silences any stream of the frame but the fault state itself
    assert contract.OUTAGE_STREAMS == tuple(
        t for t in contract.STREAMS if t not in (contract.MARKERS, contract.FAULTS))


def test_plant_topics_lose_nothing_and_name_each_link():
    for topic in contract.PLANT.values():
        assert topic.producer is Producer.PLANT and topic.stamp is Stamp.HEADER
        if topic.name.startswith('links/'):
            assert (topic.qos.reliability, topic.qos.history) == ('reliable', 'keep_all')
    assert contract.CELL_PROGRESS.qos.reliability == 'reliable'
    assert contract.link_topic(contract.PART_TRANSFER, 'line', 'a_b') == \
        '/line/links/a_b/transfer'
    assert contract.link_topic(contract.TRANSFER_ACCEPTED, '/line/', 'a_b') == \
        '/line/links/a_b/accepted'
