"""The twin's entities without ROS: names, listing, queries, states, and deleting a part (it
counts as left, the ledger balances, and runs without deletes keep their bytes)."""

import math

import numpy as np
import pytest
import yaml

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.loader import cell_from_mapping, default_cell_text
from conveyor_twin.coord import entities
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.micro.state import PartsView
from conveyor_twin.coord.entities import (delete_part, EntityQuery, EntityQueryError,
                                          snapshot_parts)


def twin_with_parts(seed: int = 3, steps: int = 800):
    built = build_twin(load_cell(), seed=seed)
    built.step(steps)
    return built


def snapshot(built) -> PartsView:
    return snapshot_parts(built.micro)


def test_part_names_round_trip_and_reject_other_names() -> None:
    assert entities.part_name(17) == 'part_17'
    assert entities.part_id_of('part_17') == 17
    for name in ('part_', 'part_0', 'part_017', 'part_1x', 'belt_main', ' part_1'):
        assert entities.part_id_of(name) is None, name


def test_lists_parts_first_then_belts_actuators_and_light_barriers() -> None:
    built = twin_with_parts()
    parts = snapshot(built)
    assert len(parts.id) > 3
    listed = entities.list_entities(built.cell, parts)
    names = [e.name for e in listed]
    assert names[:len(parts.id)] == [f'part_{i}' for i in parts.id.tolist()]
    assert names[len(parts.id):] == ['belt_main', 'actuator_pusher', 'actuator_stopper',
                                     'light_barrier_lb_infeed',
                                     'light_barrier_lb_after_deflector', 'light_barrier_lb_exit']
    part = listed[0]
    assert part.category == entities.DYNAMIC and part.tags == ('part', 'spacer')
    belt = next(e for e in listed if e.kind == entities.BELT)
    assert belt.category == entities.STATIC and belt.tags == ('belt',)


def test_query_by_regex_category_tags_and_bounds() -> None:
    built = twin_with_parts()
    cell, parts = built.cell, snapshot(built)
    listed = entities.list_entities(cell, parts)
    pos = built.twin.actuation.actuator_position

    def names(query: EntityQuery):
        return [e.name for e in query.select(cell, listed, parts, pos)]
    assert names(EntityQuery()) == [e.name for e in listed]
    assert names(EntityQuery(pattern='^light_barrier_lb_(in|ex)')) == [
        'light_barrier_lb_infeed', 'light_barrier_lb_exit']
    assert names(EntityQuery(categories=(entities.STATIC,))) == [
        'belt_main', 'light_barrier_lb_infeed', 'light_barrier_lb_after_deflector',
        'light_barrier_lb_exit']
    assert names(EntityQuery(tags=('actuator', 'belt'))) == ['belt_main', 'actuator_pusher',
                                                            'actuator_stopper']
    assert names(EntityQuery(tags=('actuator', 'pusher'), all_tags=True)) == ['actuator_pusher']
    assert names(EntityQuery(tags=('part', 'belt'), all_tags=True)) == []
    # a circle around the first part holds it; a box far off the belt holds nothing
    x, y = float(parts.x[0]), float(parts.y[0])
    assert f'part_{parts.id[0]}' in names(EntityQuery(circle=(x, y, 0.0)))
    assert names(EntityQuery(box=(10.0, 10.0, 11.0, 11.0))) == []
    with pytest.raises(EntityQueryError, match=r"filters.filter '\(' is not a valid"):
        names(EntityQuery(pattern='('))


def test_states_come_from_the_micro_scale_and_the_cell() -> None:
    built = twin_with_parts()
    cell, parts = built.cell, snapshot(built)
    pos = built.twin.actuation.actuator_position
    k = len(parts.id) // 2
    part = entities.find_entity(cell, parts, f'part_{parts.id[k]}')
    s = entities.entity_state(cell, part, parts, pos)
    assert (s.x, s.y, s.yaw, s.vx, s.vy, s.wz) == tuple(
        float(a[k]) for a in (parts.x, parts.y, parts.yaw, parts.vx, parts.vy, parts.wz))
    belt = entities.entity_state(cell, entities.find_entity(cell, parts, 'belt_main'), parts,
                                 pos)
    assert (belt.x, belt.y, belt.yaw) == (3.0, 0.0, 0.0)
    lb = entities.entity_state(cell, entities.find_entity(cell, parts, 'light_barrier_lb_exit'),
                               parts, pos)
    assert (lb.x, lb.y, lb.z) == (5.7, 0.0, 0.005) and lb.yaw == pytest.approx(math.pi / 2)
    pusher = entities.entity_state(cell, entities.find_entity(cell, parts, 'actuator_pusher'),
                                   parts, pos)
    assert (pusher.x, pusher.y) == (4.5, 0.275 - float(pos[0]))
    assert entities.find_entity(cell, parts, 'part_999999') is None
    assert entities.find_entity(cell, parts, 'belt_side') is None


def test_a_deleted_part_counts_as_left_and_the_ledger_balances() -> None:
    d = yaml.safe_load(default_cell_text())
    d['zones'] = [{'name': 'up', 'policy': 'micro', 'region': [0.0, -0.25, 1.5, 0.25]},
                  {'name': 'mid', 'policy': 'macro', 'region': [1.5, -0.25, 2.5, 0.25]},
                  {'name': 'down', 'policy': 'micro', 'region': [2.5, -0.25, 6.0, 0.25]}]
    built = build_twin(cell_from_mapping(d), seed=2, check_balance=True)
    built.step(1500)
    before = built.micro.counters()
    victim = int(built.micro.parts()[0][0])
    delete_part(built.micro, victim)
    after = built.micro.counters()
    assert after['in_flight'] == before['in_flight'] - 1
    assert after['left'] == before['left'] + 1 and after['deleted'] == 1
    assert victim not in built.micro.parts()[0].tolist()
    assert built.coupling.check_balance() == pytest.approx(0.0, abs=1e-9)
    built.step(500)  # the ledger is checked after every hand-over
    assert built.coupling.ledger()['left'] >= after['left']
    with pytest.raises(KeyError, match=rf'no part with id \[{victim}\].*nothing deleted'):
        delete_part(built.micro, victim)
    assert built.micro.counters()['in_flight'] == len(built.micro.parts()[0])


def test_runs_without_deletes_keep_their_bytes_and_a_delete_changes_them() -> None:
    a, b = twin_with_parts(seed=5, steps=600), twin_with_parts(seed=5, steps=600)
    assert 'deleted' not in a.micro.counters()
    state = a.micro.sim.state_bytes()
    assert state == b.micro.sim.state_bytes()
    delete_part(b.micro, int(b.micro.parts()[0][0]))
    assert b.micro.sim.state_bytes() != state
    a.step(10)
    b.step(10)
    assert not np.array_equal(a.micro.parts()[0], b.micro.parts()[0])


def test_a_curved_belt_and_a_transfer_unit_have_poses() -> None:
    from pathlib import Path
    examples = Path(entities.__file__).resolve().parents[1] / 'cell' / 'examples'
    cell = load_cell(examples / 'l_line.yaml')
    listed = entities.static_entities(cell)
    bend = next(e for e in listed if e.name == 'belt_bend')
    pose = entities.entity_state(cell, bend, None, np.zeros(0))
    r = 0.6 / math.sqrt(2.0)    # the middle of the centre line, heading up and to the left
    assert (pose.x, pose.y, pose.yaw) == pytest.approx((2.0 + r, 0.6 - r, math.pi / 4))
    reach = entities.footprint_radius(cell, bend)
    assert all(math.dist((pose.x, pose.y), p) <= reach for p in cell.belts[1].outline(1e-4))
    cell = load_cell(examples / 'transfer.yaml')
    xfer = next(e for e in entities.static_entities(cell) if e.name == 'actuator_xfer')
    pose = entities.entity_state(cell, xfer, None, np.array([0.015]))
    assert (pose.x, pose.y, pose.z, pose.yaw) == pytest.approx((1.5, 0.0, 0.015, math.pi / 2))
