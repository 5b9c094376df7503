"""The transfer cell end to end: examples/transfer_every_other.py against a lockstep twin.

The controller is attached in the test process (``add_node``): the harness lets it react at
every chunk, so what it commands, and when, is the same every run whatever the load. One test
starts it as its own process, as a user would.
"""

import importlib.util
from pathlib import Path
import sys
from typing import Dict, List

import numpy as np
import pytest
from simulation_interfaces.msg import EntityCategory, EntityFilters, Result

from conveyor_twin.coord.entities import OBJECT
from conveyor_twin.wire.decoders import decode_actuator_states
from test.ros.test_sim_interfaces import SimClient

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / 'examples' / 'transfer_every_other.py'
CELL = ROOT / 'conveyor_twin' / 'cell' / 'examples' / 'transfer.yaml'
CHUNK = 10            # steps per step call: the controller reacts within this many
STROKE = 0.02         # m, the transfer's lift (transfer.yaml)
LIFT_SPEED = 0.1      # m/s: stroke / travel_time (0.02 m in 0.2 s)
DT = 0.001            # s, the cell's step
PARTS = 6             # parts that leave through a sink before the run ends
# longest wait for one answer of the twin [s]: the first step of a run may compile the
# simulation kernels, minutes on a loaded machine
TIMEOUT = 300.0


def load_example():
    """The controller module (examples/ is no package)."""
    spec = importlib.util.spec_from_file_location('transfer_every_other', EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def attach(twin):
    """Attach the controller to ``twin``; return the node."""
    return twin.add_node(load_example().TransferEveryOther(context=twin.context))


def sinks(twin) -> Dict[str, int]:
    """Parts that left through each sink (the micro scale's counters)."""
    sim = twin.composed.micro_stage.sim
    return {s.name: int(c) for s, c in zip(twin.cell.sinks, sim.sink_count)}


def rising(twin, name: str) -> List[int]:
    """Ids of the parts that blocked barrier ``name``, in order."""
    return [e.part_id for e in twin.edges(name=name) if e.blocked]


def lift_history(twin, name: str = 'xfer'):
    """(commanded, actual) position of one actuator at every step received [m]."""
    rows = []
    for data in twin.messages('actuator_states'):
        msg = decode_actuator_states(data)
        i = list(msg.names).index(name)
        rows.append((msg.commanded[i], msg.actual[i]))
    return np.array(rows)


def ramps(history: np.ndarray) -> List[tuple]:
    """The moves of the actual position: (first step, steps, start, end) of each run of
    consecutive steps in which it changed."""
    actual = history[:, 1]
    moving = np.diff(actual) != 0.0
    out, k = [], 0
    while k < moving.size:
        if moving[k]:
            j = k
            while j < moving.size and moving[j]:
                j += 1
            out.append((k, j - k, actual[k], actual[j]))
            k = j
        else:
            k += 1
    return out


@pytest.mark.slow
def test_every_other_part_goes_to_the_side_line(conveyor_twin_factory):
    twin = conveyor_twin_factory(CELL, seed=1, chunk=CHUNK, timeout=TIMEOUT)
    node = attach(twin)
    twin.step_until(lambda: sum(sinks(twin).values()) >= PARTS, max_steps=30_000,
                    what=f'{PARTS} parts left through the sinks')
    left = sinks(twin)
    # half of the parts on each line, alternating, the first to the side
    assert abs(left['side_exit'] - left['main_exit']) <= 1
    assert left['side_exit'] >= PARTS // 2 - 1 and left['main_exit'] >= PARTS // 2 - 1
    arrived = rising(twin, 'lb_main_in')
    side, main = rising(twin, 'lb_side'), rising(twin, 'lb_main_out')
    assert side == arrived[0::2][:len(side)] and main == arrived[1::2][:len(main)]
    assert len(side) >= left['side_exit'] and len(main) >= left['main_exit']
    # every part accounted for: entered = left + on the belts, none vanished
    counters = twin.composed.assembled.micro_counters()
    assert counters['entered'] == counters['left'] + counters['in_flight']
    assert counters['left'] == sum(left.values()) and 'vanished' not in counters
    assert counters['in_flight'] == twin.parts().id.size
    # the controller lowered the unit for every diverted part, never on its timeout
    assert node.counts == {'in': len(arrived), 'side': len(side), 'main': len(main)}
    assert node.timeouts == 0
    commands = [r.value for r in twin.command_log() if r.target == 'xfer']
    assert all(r.result.accepted for r in twin.command_log())
    assert commands[:2 * len(side)] == [STROKE, 0.0] * len(side)
    # actuator_states: the lift goes up and down at its speed (0.1 mm per step), a full stroke
    history = lift_history(twin)
    moves = ramps(history)
    assert len(moves) >= 2 * len(side)
    step = LIFT_SPEED * DT
    for first, steps, start, end in moves:
        assert steps == pytest.approx(STROKE / step, abs=1)      # 0.2 s: the travel time
        assert {start, end} == {0.0, STROKE}
        deltas = np.diff(history[first:first + steps + 1, 1])
        assert np.allclose(np.abs(deltas[:-1]), step, rtol=1e-9, atol=1e-12)
        assert 0.0 < abs(deltas[-1]) <= step * (1 + 1e-9)
        # it moves towards what was commanded
        assert history[first + 1, 0] == end


def test_the_transfer_is_an_entity_with_a_category_and_its_lift_as_height(
        conveyor_twin_factory):
    twin = conveyor_twin_factory(CELL, seed=1, chunk=CHUNK, timeout=TIMEOUT)
    client = SimClient(twin.context)
    try:
        objects = client.call('get_entities', filters=EntityFilters(categories=[
            EntityCategory(category=EntityCategory.CATEGORY_OBJECT)])).entities
        assert 'actuator_xfer' in objects
        info = client.call('get_entity_info', entity='actuator_xfer')
        assert info.result.result == Result.RESULT_OK
        assert info.info.category.category == EntityCategory.CATEGORY_OBJECT
        assert OBJECT == 'object' and list(info.info.tags) == ['actuator', 'transfer']
        twin.set_actuator('xfer', STROKE)
        twin.step(300)                                      # 0.3 s > its travel time
        assert twin.actuator('xfer').position == STROKE
        state = client.call('get_entity_state', entity='actuator_xfer')
        assert state.result.result == Result.RESULT_OK
        pose = state.state.pose.position
        assert (pose.x, pose.y, pose.z) == pytest.approx((1.5, 0.0, STROKE))
    finally:
        client.close()


def run_digests(factory, seed: int) -> Dict[str, str]:
    """Digests of every stream of 3.8 s of the transfer cell with the controller attached (one
    part sent to the side line and the transfer lowered again)."""
    twin = factory(CELL, seed=seed, chunk=CHUNK, timeout=TIMEOUT)
    attach(twin)
    twin.step_for(3.8)
    assert rising(twin, 'lb_side') and [r.value for r in twin.command_log()] == [STROKE, 0.0]
    digests = {t: twin.digest(t) for t in ('parts', 'light_barriers', 'light_barrier_edges',
                                            'belt_states', 'actuator_states', 'command_status')}
    twin.close()
    return digests


@pytest.mark.slow
def test_same_seed_and_commands_give_the_same_bytes(conveyor_twin_factory):
    assert run_digests(conveyor_twin_factory, 4) == run_digests(conveyor_twin_factory, 4)


def test_as_its_own_process_it_raises_the_transfer_for_the_first_part(conveyor_twin_factory):
    twin = conveyor_twin_factory(CELL, seed=1, chunk=CHUNK, timeout=TIMEOUT)
    twin.start_controller([sys.executable, str(EXAMPLE)])
    twin.wait_for_node('transfer_every_other',
                       subscribes=['light_barrier_edges', 'light_barriers'],
                       publishes=['actuator_command'])
    twin.step_until(lambda: rising(twin, 'lb_main_in'), max_steps=5000,
                    what='the first part reaches lb_main_in')
    twin.wait_until(lambda: [r.value for r in twin.command_log()
                             if r.sender == 'transfer_every_other'] == [STROKE],
                    what='the controller raises the transfer')
    twin.wait_until(lambda: 'counts: in 1, side 0, main 0' in twin.controller_output(),
                    what='the controller prints its counts')
