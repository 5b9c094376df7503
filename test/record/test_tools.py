"""Offline tools on recordings: topic table, stamps, decoders, info, recover, plot (no ROS)."""

import json
import os

import numpy as np
import pytest

from conveyor_twin.cli import info as info_verb, plot as plot_verb, recover as recover_verb
from conveyor_twin.contract import Stamp
from conveyor_twin.record import reader, series, topics
from conveyor_twin.wire import cdr
from conveyor_twin.wire.decoders import (decode_actuator_states, decode_belt_states,
                                          decode_light_barrier_edge)

from .synthetic import belt_clock, conveyor_run


def test_stamp_is_read_from_the_cdr_bytes():
    t = 12 * 10**9 + 345_678_901
    assert topics.stamp_ns(Stamp.CLOCK, cdr.encode_clock(t)) == t
    data = cdr.encode_part_states(t, 'cell', 7, [1], [0], [0.1], [0.2], [0.0], [0.0], [0.0],
                                  [0.0])
    assert topics.stamp_ns(Stamp.HEADER, data) == t
    edge = cdr.encode_light_barrier_edge(t, 'cell', 'lb', True, 3)
    assert topics.stamp_ns(Stamp.HEADER, edge) == t
    assert topics.stamp_ns(Stamp.NONE, cdr.encode_belt_command('main', 0.2)) is None
    big_endian = b'\x00\x00\x00\x00' + (12).to_bytes(4, 'big') + (5).to_bytes(4, 'big')
    assert topics.stamp_ns(Stamp.CLOCK, big_endian) == 12 * 10**9 + 5
    assert topics.stamp_ns(Stamp.CLOCK, b'\x00\x01\x00\x00\x01') is None


def test_names_resolve_in_a_namespace():
    assert topics.resolve('parts', '') == '/parts'
    assert topics.resolve('parts', 'twin') == '/twin/parts'
    assert topics.resolve('/clock', '/twin') == '/clock'
    assert topics.relative('/twin/parts', '/twin') == 'parts'
    assert topics.spec_of('/twin/belt_command', 'twin').command
    names = [s.name for s in topics.select()]
    assert 'markers' not in names and '/clock' in names and 'belt_command' in names
    assert [s.name for s in topics.select(['clock', 'parts'])] == ['/clock', 'parts']
    with pytest.raises(KeyError, match='not a contract topic'):
        topics.select(['nonsense'])


def test_extra_decoders_round_trip():
    data = cdr.encode_belt_states(5, 'cell', ('a', 'bb'), [0.5, 0.25], [0.4, 0.3])
    b = decode_belt_states(data)
    assert b.stamp_ns == 5 and b.names == ('a', 'bb')
    assert b.commanded.tolist() == [0.5, 0.25] and b.actual.tolist() == [0.4, 0.3]
    a = decode_actuator_states(cdr.encode_actuator_states(9, 'cell', ('p',), [0.1], [0.05]))
    assert a.names == ('p',) and a.actual.tolist() == [0.05]
    e = decode_light_barrier_edge(cdr.encode_light_barrier_edge(77, 'cell', 'lb', True, 42))
    assert e == (77, 'cell', 'lb', True, 42)
    with pytest.raises(cdr.CdrError):
        decode_belt_states(data[:-3])


@pytest.fixture(scope='module')
def run_file(tmp_path_factory):
    path = str(tmp_path_factory.mktemp('run') / 'run.mcap')
    return path, conveyor_run(path)


def test_info_lists_counts_rates_and_run(run_file, capsys):
    path, counts = run_file
    assert info_verb.main([path, '--json']) == 0
    s = json.loads(capsys.readouterr().out)
    assert {t: v['count'] for t, v in s['topics'].items() if v['count']} == counts
    assert s['topics']['/belt_states']['rate_hz'] == pytest.approx(1000.0)
    assert s['topics']['/parts']['rate_hz'] == pytest.approx(100.0)
    assert s['cell_name'] == 'synthetic_rig' and s['seed'] == 3 and s['complete']
    assert s['compression'] == ['lz4']
    assert info_verb.main([path]) == 0
    text = capsys.readouterr().out
    assert 'Cell:' in text and 'synthetic_rig' in text and 'lz4' in text
    line = next(ln for ln in text.splitlines() if 'Topic: /parts ' in ln)
    assert f"Count: {counts['/parts']:>8}" in line and '100.00 Hz' in line


def test_info_of_a_non_recording_fails(tmp_path, capsys):
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(b'not an mcap file at all')
    assert info_verb.main([str(bad)]) == 1
    assert 'not an MCAP' in capsys.readouterr().err


def test_recover_exit_codes(tmp_path, capsys):
    path = str(tmp_path / 'belts.mcap')
    belt_clock(path, 1.0, compression='none')
    # 0: a complete file is copied whole
    assert recover_verb.main([path, '-o', str(tmp_path / 'copy.mcap')]) == 0
    assert 'complete: recovered 2000 messages' in capsys.readouterr().out
    # 3: a truncated copy gives its intact chunks back
    data = open(path, 'rb').read()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:len(data) * 2 // 3])
    out = tmp_path / 'cut_fixed.mcap'
    assert recover_verb.main([str(cut), '-o', str(out), '--json']) == 3
    report = json.loads(capsys.readouterr().out)
    assert report['result'] == 'partial' and 0 < sum(report['messages'].values()) < 2000
    assert reader.is_complete(str(out))
    assert sum(1 for _ in reader.read_messages(str(out))) == sum(report['messages'].values())
    # default output name
    assert recover_verb.main([str(cut)]) == 3
    assert os.path.exists(str(tmp_path / 'cut.recovered.mcap'))
    # 1: not MCAP, or nothing intact
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'\x00' * 100)
    assert recover_verb.main([str(junk), '-o', str(tmp_path / 'j.mcap')]) == 1
    head = tmp_path / 'head.mcap'
    head.write_bytes(data[:40])
    assert recover_verb.main([str(head), '-o', str(tmp_path / 'h.mcap')]) == 1
    assert not os.path.exists(tmp_path / 'h.mcap')


def test_series_follow_the_recorded_run(run_file):
    path, _ = run_file
    s = series.load(path, part_stride=1, density_times=[1.0, 3.0])
    assert s.belts.names == ('infeed', 'main')
    assert s.belts.actual[-1, 1] == pytest.approx(0.3)
    assert s.belts.commanded[0, 1] == 0.5 and s.belts.commanded[-1, 1] == 0.3
    assert s.barriers.blocked.any() and len(s.barriers.edges) > 2
    assert [round(g.stamp_ns / 1e9, 3) for t in (1.0, 3.0) for g in s.density[t]] == [1.0, 3.0]
    ids = series.pick_parts(s.parts, 3)
    assert len(ids) == 3
    first = s.parts.id == 1
    assert np.all(np.diff(s.parts.x[first]) >= 0)  # a part rides downstream


def test_plot_writes_meaningful_figures(run_file, tmp_path, capsys):
    path, _ = run_file
    out = tmp_path / 'figures'
    assert plot_verb.main([path, '-o', str(out), '--times', '0.5,1.5,3']) == 0
    expected = {'trajectories_xy.png', 'trajectories_x.png', 'density.png',
                'light_barriers.png', 'belt_speeds.png'}
    assert set(os.listdir(out)) == expected
    for name in expected:
        data = (out / name).read_bytes()
        assert data[:8] == b'\x89PNG\r\n\x1a\n' and len(data) > 15_000, name
    assert plot_verb.main([str(tmp_path / 'missing.mcap'), '-o', str(out)]) == 1
