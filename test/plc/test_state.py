"""PlcState: a frame sink whose refresh gives every tag's value, losing no edge."""

import threading
from typing import Dict, List, Optional

import numpy as np
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.commands import CommandRejected
from conveyor_twin.faults.model import FaultSpec
from conveyor_twin.output.frame import Frame
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import CoordinatorOutput, MacroOutput, MicroOutput
from conveyor_twin.plc import state as state_module
from conveyor_twin.plc.lockstep import StepHandshake
from conveyor_twin.plc.state import ledger_values, PlcState
from conveyor_twin.plc.tags import modbus_words, TagKind
from conveyor_twin.wire import cdr
from conveyor_twin.wire.decoders import (decode_light_barrier_edge,
                                         decode_light_barrier_states)
from test.plc.test_tags import CELLS


class EdgeCounter:
    """A sink that counts every edge and keeps the latest barrier states itself."""

    def __init__(self, names: List[str]) -> None:
        self.rising = {n: 0 for n in names}
        self.falling = {n: 0 for n in names}
        self.last_rising: Dict[str, Optional[int]] = {n: None for n in names}
        self.last_falling: Dict[str, Optional[int]] = {n: None for n in names}
        self.blocked = {n: False for n in names}

    def on_frame(self, frame: Frame) -> None:
        for stamp, data in frame.edges:
            edge = decode_light_barrier_edge(data)
            if edge.blocked:
                self.rising[edge.name] += 1
                self.last_rising[edge.name] = stamp
            else:
                self.falling[edge.name] += 1
                self.last_falling[edge.name] = stamp
        if frame.light_barriers is not None:
            _, _, _, names, blocked, _ = decode_light_barrier_states(frame.light_barriers)
            self.blocked = dict(zip(names, (bool(b) for b in blocked)))


def composed(seed: int = 1):
    """The default cell's twin with its output as the composed twin builds it."""
    cell = load_cell()
    built = build_twin(cell, seed=seed)
    output = TwinOutput([CoordinatorOutput(built.twin, diagnostics=lambda t: None),
                         MicroOutput(built.micro), MacroOutput(built.macro)])
    built.twin.step_listeners.append(output.on_step)
    return cell, built, output


def counters_of(built):
    def counters():
        return {**{f'micro_{k}': v for k, v in built.micro_counters().items()},
                **{f'macro_{k}': v for k, v in built.macro_counters().items()}}
    return counters


def spawn_at_the_barriers(cell, built) -> None:
    """Parts just upstream of every barrier, so edges come within a few hundred steps."""
    xs, ys = [], []
    for barrier in cell.light_barriers:
        for k in range(6):
            xs.append(barrier.start[0] - 0.03 - 0.04 * k)
            ys.append(-0.15 + 0.06 * (k % 5))
    n = len(xs)
    built.micro.spawn(0, np.array(xs), np.array(ys), np.zeros(n))


def assert_matches(view, state: PlcState, counter: EdgeCounter) -> None:
    tags = state.map
    for name in counter.rising:
        base = f'Barriers/{name}/'
        assert view.value(tags.by_path(base + 'RisingEdges')) == counter.rising[name]
        assert view.value(tags.by_path(base + 'FallingEdges')) == counter.falling[name]
        assert view.value(tags.by_path(base + 'Blocked')) is counter.blocked[name]
        for what, last in (('Rising', counter.last_rising), ('Falling', counter.last_falling)):
            tag = tags.by_path(f'{base}Last{what}Time')
            assert view.edge_ns(tag) == last[name]
            expected = 0.0 if last[name] is None else last[name] * 1e-9
            assert view.value(tag) == expected


def test_refresh_every_10_steps_counts_every_edge_of_a_real_twin() -> None:
    cell, built, output = composed()
    state = PlcState(cell, mode='fast', counters=counters_of(built),
                     rejected=lambda: built.twin.commands.rejected_total)
    counter = EdgeCounter([b.name for b in cell.light_barriers])
    output.subscribe(state)
    output.subscribe(counter)
    spawn_at_the_barriers(cell, built)
    built.twin.commands.submit_belt('main', 1.5)
    blocked_seen = set()
    for _ in range(300):  # 3000 steps, refreshed every 10 (10 ms)
        built.step(10)
        view = state.refresh()
        assert view.step == built.twin.step_index
        assert_matches(view, state, counter)
        blocked_seen.update(n for n, b in counter.blocked.items() if b)
    assert all(counter.rising[b.name] >= 3 for b in cell.light_barriers), counter.rising
    assert blocked_seen == {b.name for b in cell.light_barriers}
    tags = state.map
    assert view.value(tags.by_path('SimulationTime')) == pytest.approx(3.0)
    assert view.value(tags.by_path('Step')) == 3000
    assert view.value(tags.by_path('Mode')) == 'fast'
    assert view.value(tags.by_path('Belts/main/SpeedSetpoint')) == 1.5
    assert view.value(tags.by_path('Belts/main/ActualSpeed')) == 1.5
    assert view.value(tags.by_path('Actuators/stopper/Position')) == 0.0
    counters = built.micro_counters()
    assert view.value(tags.by_path('Ledger/Entered')) == counters['entered']
    assert view.value(tags.by_path('Ledger/InFlight')) == counters['in_flight']
    assert view.value(tags.by_path('FaultsActive')) == 0
    assert view.value(tags.by_path('ActiveFaults')) == ''


def test_edge_counts_keep_counting_across_a_reset() -> None:
    cell, built, output = composed()
    state = PlcState(cell, mode='lockstep', counters=None, setpoints=None)
    counter = EdgeCounter([b.name for b in cell.light_barriers])
    output.subscribe(state)
    output.subscribe(counter)
    spawn_at_the_barriers(cell, built)
    built.step(1500)
    before = state.refresh()
    built.twin.reset()
    spawn_at_the_barriers(cell, built)
    built.step(1500)
    after = state.refresh()
    assert after.step == 1500
    assert_matches(after, state, counter)
    rising = state.map.by_path('Barriers/lb_infeed/RisingEdges')
    assert after.value(rising) > before.value(rising) > 0


def edge_frame(step: int, pulses: List[tuple], barrier_names: List[str], lb_encoder,
               blocked: Optional[List[bool]] = None) -> Frame:
    """A synthetic frame of ``step`` with the edges ``(barrier, rising, stamp_ns)`` and the
    barriers' ``blocked`` flags (default: all free)."""
    frame = Frame()
    frame.step = step
    frame.time_ns = step * 1_000_000
    frame.edges = [(stamp, cdr.encode_light_barrier_edge(stamp, 'cell', barrier_names[b],
                                                         rising, step))
                   for b, rising, stamp in pulses]
    flags = np.array(blocked or [False] * len(barrier_names), dtype=bool)
    frame.light_barriers = lb_encoder.encode(frame.time_ns, step, flags,
                                             np.zeros(len(barrier_names), dtype=np.uint32))
    return frame


def test_a_2_ms_pulse_between_two_refreshes_is_never_lost() -> None:
    cell = load_cell()
    names = [b.name for b in cell.light_barriers]
    encoder = cdr.LightBarrierStatesEncoder('cell', names)
    state = PlcState(cell, mode='realtime')
    rising = state.map.by_path('Barriers/lb_exit/RisingEdges')
    falling = state.map.by_path('Barriers/lb_exit/FallingEdges')
    last_rise = state.map.by_path('Barriers/lb_exit/LastRisingTime')
    for step in range(1, 1001):
        k = step % 10
        pulses = []
        if k == 3:  # blocked at 2.4 ms into the period ...
            pulses = [(2, True, step * 1_000_000 - 600_000)]
        elif k == 5:  # ... free again 2 ms later: between two refreshes
            pulses = [(2, False, step * 1_000_000 - 600_000)]
        state.on_frame(edge_frame(step, pulses, names, encoder))
        if k == 0:
            view = state.refresh()
            assert view.value(state.map.by_path('Barriers/lb_exit/Blocked')) is False
            assert view.value(rising) == view.value(falling) == step // 10
            assert view.edge_ns(last_rise) == (step - 7) * 1_000_000 - 600_000


def test_two_threads_refreshing_concurrently_lose_nothing_and_see_whole_frames() -> None:
    cell = load_cell()
    names = [b.name for b in cell.light_barriers]
    encoder = cdr.LightBarrierStatesEncoder('cell', names)
    blocked = [False] * len(names)
    frames = []
    for step in range(1, 6001):  # barrier step % 3 toggles every step
        b = step % 3
        blocked[b] = not blocked[b]
        frames.append(edge_frame(step, [(b, blocked[b], step * 1_000_000 - 500_000)], names,
                                 encoder, list(blocked)))
    state = PlcState(cell, mode='fast')
    rising = [state.map.by_path(f'Barriers/{n}/RisingEdges') for n in names]
    falling = [state.map.by_path(f'Barriers/{n}/FallingEdges') for n in names]
    flags = [state.map.by_path(f'Barriers/{n}/Blocked') for n in names]
    done = threading.Event()
    errors: List[BaseException] = []
    views = [0, 0]

    def refresher(k: int) -> None:
        try:
            while not done.is_set():
                view = state.refresh()
                for b in range(len(names)):  # the counts belong to the flags' frame
                    assert view.value(flags[b]) == \
                        (view.value(rising[b]) - view.value(falling[b]) == 1)
                assert sum(view.value(r) + view.value(f) for r, f in zip(rising, falling)) \
                    == view.step
                views[k] += 1
        except BaseException as exc:  # noqa: B902 - handed to the test
            errors.append(exc)
    threads = [threading.Thread(target=refresher, args=(k,)) for k in range(2)]
    for thread in threads:
        thread.start()
    for frame in frames:
        state.on_frame(frame)
    done.set()
    for thread in threads:
        thread.join(timeout=60)
    assert not errors, errors[0]
    assert not any(t.is_alive() for t in threads)
    view = state.refresh()
    assert sum(view.value(t) for t in rising) == sum(view.value(t) for t in falling) == 3000
    for b in range(len(names)):
        assert view.value(rising[b]) == view.value(falling[b]) == 1000


def test_on_frame_decodes_nothing_and_takes_no_lock(monkeypatch) -> None:
    cell = load_cell()
    names = [b.name for b in cell.light_barriers]
    encoder = cdr.LightBarrierStatesEncoder('cell', names)
    state = PlcState(cell, mode='fast')

    def refuse(*args):
        raise AssertionError('on_frame decoded')
    for name in ('decode_light_barrier_edge', 'decode_light_barrier_states',
                 'decode_belt_states', 'decode_actuator_states', 'decode_fault_state'):
        monkeypatch.setattr(state_module, name, refuse)
    held = threading.Lock()
    held.acquire()  # as if a server thread were refreshing
    state._lock = held
    for step in range(1, 101):
        state.on_frame(edge_frame(step, [(0, True, step * 1_000_000)], names, encoder))
    assert len(state._edges) == 100


def test_faults_lockstep_and_rejections_show() -> None:
    cell, built, output = composed()
    handshake = StepHandshake(built.step, mode_is_lockstep=True,
                              index=lambda: built.twin.step_index)
    state = PlcState(cell, mode='lockstep', rejected=lambda: built.twin.commands.rejected_total,
                     handshake=handshake)
    output.subscribe(state)
    built.twin.faults.inject(FaultSpec(kind='belt_stall', target='main'))
    handshake.set_tick_steps(5)
    handshake.on_tick(1)
    with pytest.raises(CommandRejected):
        built.twin.commands.submit_belt('main', 9.0)
    view = state.refresh()
    tags = state.map
    assert view.step == 5
    assert view.value(tags.by_path('FaultsActive')) == 1
    assert view.value(tags.by_path('ActiveFaults')).endswith('belt_stall main')
    assert view.value(tags.by_path('RejectedWrites')) == 1
    assert view.value(tags.by_path('Lockstep/Tick')) == 1
    assert view.value(tags.by_path('Lockstep/DoneTick')) == 1
    assert view.value(tags.by_path('Lockstep/TickSteps')) == 5
    assert view.value(tags.by_path('Lockstep/Done')) is True
    assert view.value(tags.by_path('Mode')) == 'lockstep'


def test_ledger_prefers_the_coupling_ledger() -> None:
    assert ledger_values({'micro_entered': 3, 'micro_left': 1, 'micro_in_flight': 2,
                          'macro_entered': 0.5, 'macro_left': 0.0, 'macro_in_flight': 0.5}) == \
        {'entered': 3.5, 'left': 1.0, 'in_flight': 2.5}
    assert ledger_values({'micro_entered': 3, 'macro_balance_entered': 10.0,
                          'macro_balance_left': 4.0, 'macro_balance_micro': 2.0,
                          'macro_balance_macro': 3.5, 'macro_balance_pending': 0.5}) == \
        {'entered': 10.0, 'left': 4.0, 'in_flight': 6.0}
    assert ledger_values({}) == {'entered': 0.0, 'left': 0.0, 'in_flight': 0.0}


def test_unknown_mode_is_refused() -> None:
    with pytest.raises(ValueError, match="mode 'slow' is not one of realtime, fast, lockstep"):
        PlcState(load_cell(), mode='slow')


PYTHON_TYPES = {TagKind.BOOL: bool, TagKind.UINT32: int, TagKind.UINT64: int,
                TagKind.FLOAT64: float, TagKind.STRING: str}


@pytest.mark.parametrize('path', CELLS, ids=lambda p: p.name)
def test_every_value_of_every_shipped_cell_has_its_tags_type(path) -> None:
    cell = load_cell(path)
    built = build_twin(cell, seed=2)
    output = TwinOutput([CoordinatorOutput(built.twin, diagnostics=lambda t: None),
                         MicroOutput(built.micro), MacroOutput(built.macro)])
    built.twin.step_listeners.append(output.on_step)
    state = PlcState(cell, mode='lockstep', counters=counters_of(built))
    assert len(state.refresh().values) == len(state.tags)  # before the first frame
    output.subscribe(state)
    built.step(200)
    view = state.refresh()
    assert len(view.values) == len(state.tags) and view.step == 200
    for tag, value in zip(state.tags, view.values):
        assert type(value) is PYTHON_TYPES[tag.kind], (tag.path, value)
        if tag.modbus_table:
            assert len(modbus_words(tag, value)) == tag.modbus_words



def test_a_stalled_actuator_shows_in_its_stalled_and_load_tags() -> None:
    """A pusher with a force limit catching a part against a wall (the micro stall test's)."""
    from test.micro.test_actuator_stall import LIMIT, pusher_cell, spawn, STROKE
    cell = pusher_cell()
    built = build_twin(cell, seed=1)
    output = TwinOutput([CoordinatorOutput(built.twin, diagnostics=lambda t: None),
                         MicroOutput(built.micro), MacroOutput(built.macro)])
    built.twin.step_listeners.append(output.on_step)
    state = PlcState(cell, mode='lockstep', counters=None, setpoints=None)
    output.subscribe(state)
    stalled, load = (state.map.by_path(f'Actuators/pusher/{k}') for k in ('Stalled', 'Load'))
    assert stalled.modbus_table == 'discrete' and load.unit == 'N'
    spawn(built, [0.5], [0.0])
    built.twin.commands.submit_actuator('pusher', STROKE)
    seen = []
    for _ in range(700):
        built.step(1)
        view = state.refresh()
        seen.append((view.value(stalled), view.value(load)))
        assert view.value(stalled) == bool(built.twin.actuation.stalled[0])
        assert view.value(load) == built.twin.actuation.actuator_load[0]
    assert seen[0] == (False, 0.0)
    assert any(s and f > LIMIT for s, f in seen) and seen[-1][0]
