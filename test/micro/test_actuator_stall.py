"""Actuators with a force limit stall instead of crushing parts; transfer units have no shape.

The composed twin (coordinator + micro scale): the micro kernel measures the parts' load on
every actuator, the coordinator's actuation stalls an actuator whose load exceeds its
``force_limit`` (:mod:`conveyor_twin.micro.actuator_load`).
"""

import math
from dataclasses import replace

import numpy as np
import pytest

from conveyor_twin.cell.model import Actuator
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.faults.model import FaultSpec
from conveyor_twin.micro.contacts.tables import AS_ACTIVE
from conveyor_twin.split import protocol

from .conftest import disc, make_cell, wall

R = 0.01                 # part radius [m]
D = 2 * R
LIMIT = 20.0             # force limit of the actuators [N]
PUSH_SPEED = 0.8         # pusher max speed [m/s]
WALL_Y = -0.2            # centre line of the far wall (thickness 10 mm: face at -0.195)
STROKE = 0.38            # the paddle's front ends 5 mm short of the wall's face


def pusher(limit=LIMIT, restitution=0.0):
    """A paddle 20 mm deep, 150 mm wide, at y = 0.2 pushing toward -y."""
    return Actuator(name='pusher', kind='pusher', base=(0.5, 0.2), axis=(0.0, -1.0),
                    length=0.02, width=0.15, position_range=(0.0, STROKE),
                    max_speed=PUSH_SPEED, initial_position=0.0, restitution=restitution,
                    force_limit=limit)


def pusher_cell(limit=LIMIT, far_wall=True, **kw):
    obstacles = [wall('far', (0.0, WALL_Y), (2.0, WALL_Y), thickness=0.01)] if far_wall else []
    return make_cell(part_types=[disc(radius=R, mass=0.01, restitution=0.0, mu_s=0.3,
                                      mu_k=0.2)],
                     obstacles=obstacles, actuators=[pusher(limit)], **kw)


def spawn(twin, xs, ys):
    twin.micro.spawn(0, np.asarray(xs, float), np.asarray(ys, float), np.zeros(len(xs)))


def front(twin):
    """y of the paddle's front face [m]."""
    return 0.2 - twin.twin.actuation.actuator_position[0] - 0.01


def deepest_overlap(twin):
    """Deepest overlap of any part with the wall, the paddle or another part [m]."""
    v = twin.micro.sim.parts_view()
    worst = float(np.max(R - (v.y - (WALL_Y + 0.005)), initial=0.0))
    under = np.abs(v.x - 0.5) < 0.075 + R
    if under.any():
        worst = max(worst, float(np.max(R - (front(twin) - v.y[under]))))
    for i in range(v.x.size):
        d = np.hypot(v.x[i] - v.x[i + 1:], v.y[i] - v.y[i + 1:])
        if d.size:
            worst = max(worst, float(D - d.min()))
    return worst


def run(twin, steps, watch=None):
    for _ in range(steps):
        twin.step(1)
        if watch is not None:
            watch(twin)


def test_pusher_stalls_at_a_closed_wall_instead_of_crushing_the_part():
    twin = build_twin(pusher_cell(), seed=1)
    spawn(twin, [0.5], [0.0])
    twin.twin.commands.submit_actuator('pusher', STROKE)
    seen = {'overlap': 0.0, 'speed': 0.0, 'stalled': 0, 'overload': 0.0}

    def watch(t):
        seen['overlap'] = max(seen['overlap'], deepest_overlap(t))
        v = t.micro.sim.parts_view()
        seen['speed'] = max(seen['speed'], float(np.hypot(v.vx, v.vy).max()))
        a = t.twin.actuation
        if a.stalled[0]:
            seen['stalled'] += 1
            seen['overload'] = max(seen['overload'], float(a.overload[0]))
    run(twin, 900, watch)   # 0.475 s of stroke; the part meets the wall after ~0.45 s
    assert seen['stalled'] > 300, seen
    assert twin.twin.actuation.stalled[0]
    assert seen['overload'] > LIMIT
    assert seen['overlap'] <= 0.05 * D, seen
    assert seen['speed'] <= PUSH_SPEED * (1 + 1e-9), seen  # belt still: no throw-off
    assert twin.twin.actuation.actuator_position[0] < STROKE - 0.005
    status = twin.twin.actuation.status()
    assert status.level == 1 and 'pusher stalled' in status.message, status
    assert f'force_limit {LIMIT:g} N' in status.message
    # commanded back: it retracts and the stall clears
    twin.twin.commands.submit_actuator('pusher', 0.0)
    run(twin, 30)
    assert not twin.twin.actuation.stalled[0]
    assert twin.twin.actuation.actuator_position[0] < STROKE - 0.02
    assert twin.twin.actuation.status().level == 0


def test_unlimited_pusher_still_crushes_as_before():
    """force_limit inf (the default) keeps the kinematic pusher: it reaches its stroke."""
    twin = build_twin(pusher_cell(limit=math.inf), seed=1)
    spawn(twin, [0.5], [0.0])
    twin.twin.commands.submit_actuator('pusher', STROKE)
    run(twin, 600)
    assert twin.twin.actuation.actuator_position[0] == STROKE
    assert not twin.twin.actuation.stalled.any()
    assert twin.twin.actuation.actuator_load[0] > LIMIT   # measured all the same
    assert twin.twin.actuation.status() is None


@pytest.mark.parametrize('ys', [[0.0], [0.0, -D - 0.001, -2 * D - 0.002]],
                         ids=['free part', 'short queue'])
def test_pushing_free_parts_does_not_stall(ys):
    twin = build_twin(pusher_cell(far_wall=False, width=1.0), seed=1)
    spawn(twin, [0.5] * len(ys), ys)
    twin.twin.commands.submit_actuator('pusher', STROKE)
    peak = [0.0]

    def watch(t):
        assert not t.twin.actuation.stalled[0]
        peak[0] = max(peak[0], float(t.twin.actuation.actuator_load[0]))
    run(twin, 600, watch)
    assert twin.twin.actuation.actuator_position[0] == STROKE
    assert 0.0 < peak[0] < LIMIT
    v = twin.micro.sim.parts_view()
    assert (v.y < 0.2 - STROKE - 0.01 + 1e-3).all()  # all pushed ahead of the paddle


def diverter_cell(limit=LIMIT):
    """A queue in a channel 50 mm wide held by an end wall; a diverter arm lying along the
    channel's left wall swings into it (negative angles)."""
    arm = Actuator(name='arm', kind='diverter', base=(0.5, 0.025), axis=(1.0, 0.0),
                   length=0.1, width=0.01, position_range=(-1.0, 0.0), max_speed=3.0,
                   initial_position=0.0, restitution=0.0, force_limit=limit)
    walls = [wall('end', (0.7, -0.25), (0.7, 0.25), thickness=0.01),
             wall('left', (0.0, 0.03), (0.7, 0.03), thickness=0.01),
             wall('right', (0.0, -0.03), (0.7, -0.03), thickness=0.01)]
    return make_cell(part_types=[disc(radius=R, mass=0.01, restitution=0.0, mu_s=0.3,
                                      mu_k=0.2)],
                     obstacles=walls, actuators=[arm], speed=0.3)


def test_diverter_swinging_into_a_blocked_queue_stalls():
    twin = build_twin(diverter_cell(), seed=1)
    xs = 0.7 - 0.005 - R - np.arange(12) * (D + 0.0005)
    spawn(twin, xs, np.zeros(xs.size))
    run(twin, 300)                         # the queue settles against the end wall
    twin.twin.commands.submit_actuator('arm', -1.0)
    worst = [0.0]

    def watch(t):
        v = t.micro.sim.parts_view()
        for i in range(v.x.size):
            d = np.hypot(v.x[i] - v.x[i + 1:], v.y[i] - v.y[i + 1:])
            if d.size:
                worst[0] = max(worst[0], float(D - d.min()))
    run(twin, 600, watch)
    a = twin.twin.actuation
    assert a.stalled[0]
    assert a.overload[0] > LIMIT
    assert a.actuator_position[0] > -1.0
    assert twin.micro.sim.n == 12
    assert worst[0] <= 0.05 * D
    twin.twin.commands.submit_actuator('arm', 0.0)
    run(twin, 600)
    assert not a.stalled[0] and a.actuator_position[0] == 0.0


def test_a_stall_clears_by_itself_when_the_obstacle_goes():
    """The part is deleted while the pusher stalls on it: the pusher resumes its stroke."""
    twin = build_twin(pusher_cell(), seed=1)
    spawn(twin, [0.5], [0.0])
    twin.twin.commands.submit_actuator('pusher', STROKE)
    run(twin, 700)
    assert twin.twin.actuation.stalled[0]
    twin.micro.sim.delete([int(twin.micro.sim.parts_view().id[0])])
    run(twin, 20)
    assert not twin.twin.actuation.stalled[0]
    assert twin.twin.actuation.actuator_position[0] == STROKE


def test_actuator_faults_act_on_a_stalled_actuator():
    twin = build_twin(pusher_cell(), seed=1)
    spawn(twin, [0.5], [0.0])
    twin.twin.commands.submit_actuator('pusher', STROKE)
    run(twin, 700)
    assert twin.twin.actuation.stalled[0]
    held = twin.twin.actuation.actuator_position[0]
    stuck = twin.twin.faults.inject(FaultSpec('actuator_stuck', 'pusher'))
    twin.twin.commands.submit_actuator('pusher', 0.0)
    run(twin, 50)
    assert twin.twin.actuation.actuator_position[0] == held   # stuck: the retract waits
    twin.twin.faults.clear(stuck.id)
    run(twin, 50)
    assert twin.twin.actuation.actuator_position[0] < held - 0.02
    assert not twin.twin.actuation.stalled[0]


def test_penalty_model_measures_the_load_too():
    twin = build_twin(pusher_cell(contact='penalty'), seed=1)
    spawn(twin, [0.5], [0.0])
    twin.twin.commands.submit_actuator('pusher', STROKE)
    stalled = [0]

    def watch(t):
        stalled[0] += bool(t.twin.actuation.stalled[0])
    run(twin, 900, watch)
    assert stalled[0] > 100
    assert twin.twin.actuation.overload[0] > LIMIT
    assert deepest_overlap(twin) <= 0.05 * D


def test_cells_without_contact_at_actuators_keep_their_trajectories():
    """A force limit changes nothing where no part touches the actuator."""
    hashes = []
    for limit in (math.inf, LIMIT):
        twin = build_twin(pusher_cell(limit=limit, speed=0.3), seed=3)
        spawn(twin, [0.1, 0.2, 1.2], [0.0, -0.1, 0.1])  # away from the paddle's lane
        twin.twin.commands.submit_actuator('pusher', 0.1)
        run(twin, 400)
        assert not twin.twin.actuation.stalled.any()
        hashes.append(twin.micro.sim.state_hash())
    assert hashes[0] == hashes[1]


def test_transfer_units_have_no_collision_shape():
    lift = Actuator(name='lift', kind='transfer', base=(0.5, 0.0), axis=(0.0, 1.0),
                    length=0.2, width=0.2, position_range=(0.0, 0.01), max_speed=0.02,
                    initial_position=0.0, engage_height=0.005, surface_speed=0.3,
                    force_limit=LIMIT)
    cell = make_cell(part_types=[disc(radius=R, mass=0.01)], actuators=[lift])
    twin = build_twin(cell, seed=1)
    spawn(twin, [0.5], [0.0])
    twin.twin.commands.submit_actuator('lift', 0.01)
    positions = []
    for _ in range(600):
        twin.step(1)
        positions.append(twin.twin.actuation.actuator_position[0])
        assert twin.micro.sim.act_state[0, AS_ACTIVE] == 0.0
    # it ramps like a stopper's lift: max_speed * dt per step, then holds at the top
    assert positions[0] == pytest.approx(0.02 * cell.settings.step)
    assert positions[-1] == 0.01 and positions.index(0.01) in (499, 500)
    assert twin.twin.actuation.actuator_load[0] == 0.0
    assert not twin.twin.actuation.stalled[0]


def test_split_reply_carries_the_loads():
    loads = np.array([0.0, 12.5, 1e6])
    reply = protocol.with_loads(loads, b'{"entered": 1}')
    rest, back = protocol.split_loads(reply)
    assert rest == b'{"entered": 1}' and back.tolist() == loads.tolist()
    assert protocol.split_loads(b'{"entered": 1}') == (b'{"entered": 1}', None)
    rest, back = protocol.split_loads(protocol.with_loads(np.zeros(0), b''))
    assert rest == b'' and back.size == 0


def test_default_cells_have_no_force_limit(default_cell):
    assert all(math.isinf(a.force_limit) for a in default_cell.actuators)
    assert replace(default_cell.actuators[0], force_limit=5.0).force_limit == 5.0
