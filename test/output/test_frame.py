"""The twin's frames: one per step, every stream once with its stamp, the same bytes as the
encoders, each stage's part alone in its own output; slow sinks never block the step."""

import threading

import numpy as np
import pytest
import yaml

from conveyor_twin import contract
from conveyor_twin.cell import default_cell_text
from conveyor_twin.cell.loader import cell_from_mapping
from conveyor_twin.coord.commands import CommandKind
from conveyor_twin.coord.stages import MacroStage, MicroStage
from conveyor_twin.coord.twin import Twin
from conveyor_twin.output.frame import Frame
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import CoordinatorOutput, MacroOutput, MicroOutput
from conveyor_twin.output.queued import QueuedSink
from conveyor_twin.record import reader
from conveyor_twin.record.sink import RecordingSink
from conveyor_twin.record.writer import ACCEPTED_BELT_COMMANDS, McapRecorder
from conveyor_twin.wire import cdr

SEED = 4
STEPS = 600
DT_NS = 1_000_000


def _cell():
    """The default cell at 400 parts/s with a macro zone between two light barriers."""
    d = yaml.safe_load(default_cell_text())
    d['sources'][0]['rate'] = 400.0
    d['zones'] = [{'name': 'up', 'policy': 'micro', 'region': [0.0, -0.25, 2.5, 0.25]},
                  {'name': 'mid', 'policy': 'macro', 'region': [2.5, -0.25, 3.4, 0.25]}]
    return cell_from_mapping(d)


def _twin(cell, producers=('coordinator', 'micro', 'macro')):
    micro, macro = MicroStage(cell, SEED), MacroStage(cell)
    twin = Twin(cell, seed=SEED, stages=[micro, macro])
    made = {'coordinator': lambda: CoordinatorOutput(twin, diagnostics=lambda t: b'diag%d' % t),
            'micro': lambda: MicroOutput(micro), 'macro': lambda: MacroOutput(macro)}
    output = TwinOutput([made[p]() for p in producers])
    twin.step_listeners.append(output.on_step)
    return twin, micro, macro, output


class Keeper:
    """A sink keeping a copy of every frame."""

    def __init__(self) -> None:
        self.frames = []

    def on_frame(self, frame: Frame) -> None:
        self.frames.append(frame.copy())


def test_a_frame_per_step_holds_every_stream_once_with_its_stamp():
    cell = _cell()
    twin, micro, macro, output = _twin(cell)
    keeper = Keeper()
    output.subscribe(keeper)
    twin.commands.submit_belt('main', 1.0)
    micro.spawn(cell.part_type_index('spacer'), np.array([1.9]), np.array([0.05]),
                np.zeros(1))  # just before lb_infeed: edges within the run
    twin.step(contract.DIAGNOSTICS_PERIOD_STEPS)
    frames = keeper.frames
    assert [f.step for f in frames] == list(range(1, contract.DIAGNOSTICS_PERIOD_STEPS + 1))
    edges = 0
    for f in frames:
        t = f.step * DT_NS
        assert f.time_ns == t and f.input.step == f.step
        assert cdr.decode_clock(f.clock) == t
        parts = cdr.decode_part_states(f.parts)
        assert (parts.step, parts.stamp_ns) == (f.step, t)
        assert cdr.decode_light_barrier_states(f.light_barriers)[2] == f.step
        for stamp, data in f.edges:
            assert stamp == int.from_bytes(data[4:8], 'little') * 10**9 + \
                int.from_bytes(data[8:12], 'little')
            assert t - DT_NS < stamp <= t
            edges += 1
        assert len(f.density) == 1
        grid = cdr.decode_density_grid(f.density[0])
        assert (grid.step, grid.stamp_ns, grid.zone) == (f.step, t, 'mid')
        assert (f.diagnostics is not None) == (f.step % contract.DIAGNOSTICS_PERIOD_STEPS == 0)
    assert edges >= 2, 'the run should cover edges'
    assert frames[-1].diagnostics == b'diag%d' % frames[-1].time_ns
    assert [(f.step, [c.kind for c in f.commands]) for f in frames if f.commands] == \
        [(1, [CommandKind.BELT])]
    # messages() lists every message with its contract topic, the stamp and the bytes
    f = frames[-1]
    listed = list(f.messages())
    assert [m[0] for m in listed][:3] == [contract.CLOCK, contract.BELT_STATES,
                                          contract.ACTUATOR_STATES]
    assert (contract.PARTS, f.time_ns, f.parts) in listed
    assert (contract.DENSITY, f.time_ns, f.density[0]) in listed


def test_the_frame_bytes_are_those_of_the_encoders():
    cell = _cell()
    twin, micro, macro, output = _twin(cell)
    frame_id = cell.settings.frame_id
    names = [b.name for b in cell.light_barriers]
    checked = []

    def check(inp, _commands):
        f = output.frame
        assert f.parts == cdr.encode_part_states(inp.time_ns, frame_id, inp.step,
                                                 *micro.parts())
        assert f.light_barriers == cdr.encode_light_barrier_states(
            inp.time_ns, frame_id, inp.step, names, micro.barrier_blocked(),
            micro.barrier_edge_count())
        assert f.belt_states == cdr.encode_belt_states(
            inp.time_ns, frame_id, [b.name for b in cell.belts], twin.actuation.belt_target,
            inp.belt_speed)
        checked.append(inp.step)

    twin.step_listeners.append(check)  # after the output's listener: the frame of this step
    twin.step(200)
    assert checked == list(range(1, 201))


@pytest.mark.parametrize('part', ['coordinator', 'micro', 'macro'])
def test_each_stage_part_alone_equals_its_part_of_the_full_frame(part):
    """Split layout: a process's output carries its stage's streams only, byte for byte."""
    fields = {'coordinator': ('clock', 'belt_states', 'actuator_states', 'diagnostics', 'faults'),
              'micro': ('parts', 'light_barriers', 'edges'), 'macro': ('density',)}
    cell = _cell()
    twin, micro, macro, full = _twin(cell)
    # the part alone, on the same stages (as the split process's output is)
    made = {'coordinator': CoordinatorOutput(twin, diagnostics=lambda t: b'diag%d' % t),
            'micro': MicroOutput(micro), 'macro': MacroOutput(macro)}
    alone = TwinOutput([made[part]])
    twin.step_listeners.append(alone.on_step)
    a, b = Keeper(), Keeper()
    full.subscribe(a)
    alone.subscribe(b)
    twin.step(STEPS)
    for x, y in zip(a.frames, b.frames):
        for name in Frame.__slots__:
            if name in fields[part] or name in ('step', 'time_ns', 'input'):
                assert getattr(x, name) == getattr(y, name), name
            elif name == 'commands':
                continue
            else:
                assert not getattr(y, name), name  # not produced in that process


def test_reruns_give_identical_frames():
    def run():
        twin, _, _, output = _twin(_cell())
        keeper = Keeper()
        output.subscribe(keeper)
        twin.step(300)
        return [list(f.messages()) for f in keeper.frames]
    assert run() == run()


def test_a_slow_sink_drops_and_counts_but_never_blocks_the_step():
    twin, _, _, output = _twin(_cell(), producers=('coordinator', 'micro'))
    entered, release = threading.Event(), threading.Event()
    taken = []

    def slow(frame: Frame) -> None:
        entered.set()
        release.wait(30.0)
        taken.append(frame.step)

    sink = QueuedSink(slow, queue_size=5)
    output.subscribe(sink)
    twin.step(1)
    assert entered.wait(30.0)  # the worker holds frame 1; the queue is empty
    twin.step(20)  # the step goes on: 5 frames queued, 15 dropped
    assert sink.dropped == 15
    release.set()
    sink.close()
    assert taken == [1, 2, 3, 4, 5, 6] and sink.delivered == 6 and sink.error is None
    output.unsubscribe(sink)
    twin.step(1)
    assert sink.dropped == 15


def test_the_recording_sink_records_every_frame_with_its_stamp(tmp_path):
    cell = _cell()
    twin, _, _, output = _twin(cell)
    path = tmp_path / 'frames.mcap'
    recorder = McapRecorder(str(path), cell_yaml=default_cell_text(), seed=SEED,
                            step_ns=DT_NS, metadata={'recorded_by': 'test'})
    sink = RecordingSink(recorder, namespace='/twin')
    output.subscribe(sink)
    keeper = Keeper()
    output.subscribe(keeper)
    twin.commands.submit_belt('main', 0.3)
    twin.step(300)
    sink.on_message(contract.MARKERS, 123, b'\x00\x01\x00\x00markers')
    recorder.close()
    expected = {}
    for f in keeper.frames:
        for topic, stamp, data in f.messages():
            name = '/clock' if topic is contract.CLOCK else '/twin/' + topic.name
            expected.setdefault(name, []).append((stamp, data))
    got = {}
    for m in reader.read_messages(str(path)):
        got.setdefault(m.topic, []).append((m.log_time, m.data))
    commands = got.pop(ACCEPTED_BELT_COMMANDS)
    assert commands == [(DT_NS, cdr.encode_belt_command('main', 0.3))]
    assert got.pop('/twin/markers') == [(123, b'\x00\x01\x00\x00markers')]
    assert got == expected


class _Calls:
    """A recorder that keeps what a sink hands it, in order."""

    def __init__(self) -> None:
        self.calls = []

    def add_topic(self, name, type_name, qos=None) -> bool:
        return True

    def record(self, name, stamp_ns, data) -> None:
        self.calls.append((name, stamp_ns, data))

    def record_accepted_command(self, kind, stamp_ns, data) -> None:
        pass


def test_sinks_take_the_streams_in_the_order_and_places_of_the_frame_table():
    """The recording holds a step's messages in the order of ``contract.FRAME``; a silenced
    stream's place holds its empty value."""
    from conveyor_twin.faults.model import FaultSpec
    cell = _cell()
    twin, micro, _, output = _twin(cell)
    recorder = _Calls()
    output.subscribe(RecordingSink(recorder, namespace='/twin'))
    keeper = Keeper()
    output.subscribe(keeper)
    twin.commands.submit_belt('main', 1.0)
    micro.spawn(cell.part_type_index('spacer'), np.array([1.9]), np.array([0.05]),
                np.zeros(1))
    twin.faults.inject(FaultSpec('stream_outage', contract.DENSITY.name, duration=0.01),
                       step=50)
    twin.step(STEPS)
    expected = [('/clock' if topic is contract.CLOCK else '/twin/' + topic.name, stamp, data)
                for f in keeper.frames for topic, stamp, data in f.messages()]
    assert recorder.calls == expected
    order = {slot.topic: i for i, slot in enumerate(contract.FRAME)}
    for f in keeper.frames:
        ranks = [order[topic] for topic, _, _ in f.messages()]
        assert ranks == sorted(ranks)
    silenced = [f.step for f in keeper.frames if f.density == ()]
    assert silenced == list(range(50, 60))
    assert {t.name for t, _, _ in keeper.frames[0].messages()} >= {
        contract.FAULTS.name, contract.DENSITY.name}
