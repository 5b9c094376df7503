"""``conveyor-twin run --record``: what it records, its options, drops counted and reported."""

import json
import subprocess
import sys

import pytest

from conveyor_twin.record import reader
from conveyor_twin.record.writer import ACCEPTED_ACTUATOR_COMMANDS, ACCEPTED_BELT_COMMANDS
from conveyor_twin.wire import cdr

pytestmark = pytest.mark.ros

DT_NS = 1_000_000
EVERY_STEP = ('/parts', '/light_barriers', '/belt_states', '/actuator_states', '/clock')


def run(ros_processes, *args):
    process = ros_processes.start(
        [sys.executable, '-m', 'conveyor_twin.cli', 'run', '--mode', 'fast', '--quiet',
         '--json', *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = process.communicate(timeout=300)
    return process.returncode, out, err


@pytest.mark.smoke
def test_every_published_stream_and_the_commands_are_recorded(tmp_path, ros_processes,
                                                               ros_context):
    path = tmp_path / 'run.mcap'
    code, out, err = run(ros_processes, '--duration', '1', '--record', str(path), '--seed', '3',
                         '--command', '250:belt:main=1.5', '250:actuator:pusher=0.1',
                         '600:belt:main=0.4')
    assert code == 0, err
    summary = json.loads(out)
    rec = summary['recording']
    assert rec['dropped'] == 0 and rec['compression'] == 'lz4'
    info = reader.info(str(path))
    assert info['complete'] and info['seed'] == 3 and info['compression'] == ['lz4']
    for topic in EVERY_STEP:
        assert info['topics'][topic]['count'] == rec['topics'][topic]['recorded'] == 1000
    markers = info['topics']['/markers']['count']
    # at most one per 1/30 s of sim time; the micro node builds them off the stepping thread and
    # publishes only the latest due one, so fast mode on a busy machine skips some (which ones
    # depends on the wall clock; resimulate below checks each recorded one is a due one)
    assert 0 < markers <= 31
    assert info['topics']['/diagnostics']['count'] == 1
    commands = [(m.topic, m.log_time // DT_NS, m.data)
                for m in reader.read_messages(str(path), topics=[ACCEPTED_BELT_COMMANDS,
                                                                 ACCEPTED_ACTUATOR_COMMANDS])]
    decoded = [(t, s, cdr.decode_belt_command(d) if 'belt' in t else
                cdr.decode_actuator_command(d)) for t, s, d in commands]
    assert sorted(decoded) == sorted([(ACCEPTED_BELT_COMMANDS, 250, ('main', 1.5)),
                                      (ACCEPTED_ACTUATOR_COMMANDS, 250, ('pusher', 0.1)),
                                      (ACCEPTED_BELT_COMMANDS, 600, ('main', 0.4))])
    meta = reader.read_metadata(str(path))['conveyor_twin']
    assert meta['recorded_by'] == 'conveyor-twin run' and meta['markers_rate'] == '30.0'
    assert b'seed_test_rig' in reader.read_attachment(str(path), 'cell.yaml')

    from conveyor_twin.record.resimulate import resimulate
    report = resimulate(str(path), context=ros_context)
    assert report.ok, str(report.difference)
    assert report.commands == 3 and report.compared['/markers'] == markers


def test_selection_decimation_and_drops_are_counted(tmp_path, ros_processes, ros_context):
    path = tmp_path / 'small.mcap'
    code, out, err = run(ros_processes, '--duration', '0.6', '--record', str(path),
                         '--record-topics', 'parts', 'clock', 'belt_states',
                         '--record-decimate', 'parts=10', '--record-compression', 'zstd',
                         '--record-queue-size', '3', '--command', '100:belt:main=1.0')
    assert code == 0, err
    rec = json.loads(out)['recording']
    topics = rec['topics']
    assert set(topics) == {'/parts', '/clock', '/belt_states', ACCEPTED_BELT_COMMANDS}
    assert topics['/parts']['decimated'] == 540
    total_dropped = sum(t['dropped'] for t in topics.values())
    assert rec['dropped'] == total_dropped > 0  # a 3-message queue cannot keep up
    assert topics[ACCEPTED_BELT_COMMANDS] == {'recorded': 1, 'decimated': 0, 'dropped': 0}
    info = reader.info(str(path))
    assert info['compression'] == ['zstd']
    for topic in ('/parts', '/clock', '/belt_states'):
        assert info['topics'][topic]['count'] == topics[topic]['recorded'], topic
    sequences = [m.sequence for m in reader.read_messages(str(path), topics=['/parts'])]
    assert all(s % 10 == 1 for s in sequences)  # every 10th offered, from the first
    stats = json.loads(reader.read_metadata(str(path))['conveyor_twin_recorder']['stats'])
    assert stats['topics']['/parts']['dropped'] == topics['/parts']['dropped']
    # what was recorded still re-simulates: drops and decimation only skip
    from conveyor_twin.record.resimulate import resimulate
    report = resimulate(str(path), context=ros_context)
    assert report.ok, str(report.difference)
    assert sum(report.compared.values()) == sum(
        topics[t]['recorded'] for t in ('/parts', '/clock', '/belt_states'))


@pytest.mark.parametrize('args,message', [
    (['--command', '0:belt:main=1'], 'STEP:KIND:NAME=VALUE'),
    (['--command', '10:belt:nope=1'], 'unknown belt'),
    (['--command', '10:actuator:pusher=9'], 'outside'),
    (['--record', 'x.mcap', '--record-topics', 'nope'], 'not a contract topic'),
    (['--record', 'x.mcap', '--record-decimate', 'parts=0'], 'NAME=K'),
    (['--record', '/nonexistent/dir/x.mcap'], 'cannot create recording'),
    (['--record', '/dev/full'], 'cannot write recording /dev/full'),  # a full disk
    (['--split', '--record', 'x.mcap'], 'composed layout'),
])
def test_bad_options_are_clear_errors(tmp_path, capfd, args, message):
    from conveyor_twin.cli import run as run_verb
    code = run_verb.main(['--mode', 'fast', '--quiet', '--duration', '0.01', *args])
    assert code == 2 and message in capfd.readouterr().err
