"""``spawn_parts`` and ``reset`` calls in a recording: spawns re-simulate, resets are refused."""

import numpy as np
import pytest

from conveyor_twin.cell import default_cell_text, load_cell_text
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.record import reader
from conveyor_twin.record.errors import RecordingError
from conveyor_twin.record.writer import ACCEPTED_RESETS, ACCEPTED_SPAWNS, McapRecorder
from conveyor_twin.ros.compose import ComposedTwin
from conveyor_twin.ros.run_recording import TwinRecording
from conveyor_twin.record.resimulate import resimulate
from conveyor_twin.wire import cdr

pytestmark = pytest.mark.ros

SEED = 5
STEPS = 400
# (step after which the call is made, x [m], y [m]) of each spawn_parts call
SPAWNS = ((0, (0.3, 0.3), (0.05, -0.05)), (120, (0.8,), (0.0,)), (121, (1.0, 1.05), (0.1, 0.1)))


def record(path, context, *, reset_at=None):
    """Record a lockstep run of the default cell with SPAWNS (and a reset); return spawn ids."""
    from conveyor_twin_msgs.srv import Reset, SpawnParts

    text = default_cell_text()
    twin = ComposedTwin(load_cell_text(text), seed=SEED, mode=TimeMode.LOCKSTEP,
                        context=context, markers_rate=0.0)
    recorder = McapRecorder(str(path), cell_yaml=text, seed=SEED, step_ns=twin.twin.dt_ns,
                            metadata={'recorded_by': 'test', 'markers_rate': '0.0',
                                      'namespace': twin.coordinator.get_namespace()})
    recording = TwinRecording(twin, recorder)
    placed = []
    try:
        for step in range(STEPS):
            for at, x, y in SPAWNS:
                if at == step:
                    request = SpawnParts.Request(part_type='spacer', x=list(x), y=list(y))
                    response = twin.coordinator._on_spawn(request, SpawnParts.Response())
                    assert response.success, response.message
                    placed.extend(response.id)
            if step == reset_at:
                response = twin.coordinator._on_reset(Reset.Request(seed=SEED),
                                                      Reset.Response())
                assert response.success, response.message
            twin.twin.step(1)
    finally:
        twin.stop()
        recording.close()
    return placed


def test_spawn_calls_are_recorded_and_resimulate_bit_for_bit(tmp_path, ros_context):
    path = tmp_path / 'spawns.mcap'
    placed = record(path, ros_context)
    assert len(placed) == 5
    calls = [(m.log_time, cdr.decode_spawn_request(m.data))
             for m in reader.read_messages(str(path), topics=[ACCEPTED_SPAWNS])]
    assert [t // 1_000_000 for t, _ in calls] == [at for at, _, _ in SPAWNS]
    for (_, (name, x, y, yaw)), (_, xs, ys) in zip(calls, SPAWNS):
        assert name == 'spacer' and list(x) == list(xs) and list(y) == list(ys)
        assert not yaw.any()
    # the placed parts are in the recorded stream: their ids appear in parts
    last = cdr.decode_part_states(list(reader.read_messages(str(path),
                                                             topics=['/parts']))[-1].data)
    assert set(placed) <= set(last.id.tolist())

    report = resimulate(str(path), context=ros_context)
    assert report.ok, str(report.difference)
    assert report.spawns == 3 and report.compared['/parts'] == STEPS


def test_a_resimulation_without_the_spawns_differs(tmp_path, ros_context, monkeypatch):
    path = tmp_path / 'spawns.mcap'
    record(path, ros_context)
    from conveyor_twin.record import resimulate as module
    monkeypatch.setattr(module, '_spawns', lambda *args: {})
    report = resimulate(str(path), context=ros_context)
    assert not report.ok and report.difference.step == 1  # the parts placed before step 1


def test_a_recorded_reset_is_refused_with_a_clear_error(tmp_path, ros_context):
    path = tmp_path / 'reset.mcap'
    record(path, ros_context, reset_at=200)
    resets = [cdr.decode_reset_request(m.data)
              for m in reader.read_messages(str(path), topics=[ACCEPTED_RESETS])]
    assert resets == [('', SEED)]
    with pytest.raises(RecordingError, match='reset'):
        resimulate(str(path), context=ros_context)


def test_spawn_request_cdr_round_trips_through_rclpy():
    from rclpy.serialization import deserialize_message, serialize_message
    from conveyor_twin_msgs.srv import Reset, SpawnParts

    data = cdr.encode_spawn_request('box', [0.1, 0.2], [0.3, -0.4], [0.5, 0.0])
    msg = deserialize_message(data, SpawnParts.Request)
    assert msg.part_type == 'box' and list(msg.x) == [0.1, 0.2] and list(msg.yaw) == [0.5, 0.0]
    # rclpy leaves its alignment padding uninitialised: compare values, not padding bytes
    for encoded in (data, serialize_message(msg)):
        name, x, y, yaw = cdr.decode_spawn_request(encoded)
        assert name == 'box' and np.array_equal(x, [0.1, 0.2])
        assert np.array_equal(y, [0.3, -0.4]) and np.array_equal(yaw, [0.5, 0.0])
    reset = deserialize_message(cdr.encode_reset_request('a.yaml', 7), Reset.Request)
    assert (reset.cell_file, reset.seed) == ('a.yaml', 7)
    assert cdr.decode_reset_request(serialize_message(reset)) == ('a.yaml', 7)
