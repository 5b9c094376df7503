"""The split layout's roles in one process: the coordinator's remote stage and the two scale
roles talk only bytes (an in-memory transport), and give the composed twin's state and frames."""

from typing import Callable, Dict, List, Set

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.layout import Layout, Role
from conveyor_twin.coord.requests import check_spawn
from conveyor_twin.output.hub import TwinOutput
from conveyor_twin.output.producers import MacroOutput, MicroOutput
from conveyor_twin.split.remote import RemoteStage
from conveyor_twin.split.roles import build_scale_role, CoordinatorRole, MacroRole, MicroRole

from ..coord.test_assembly import mid_macro_cell


class Link:
    """A scale role's link: replies to the coordinator, hand-over to the other role."""

    def __init__(self, to_coordinator: Callable[[bytes], None]) -> None:
        self.to_coordinator = to_coordinator
        self.peer = None
        self.errors: List[str] = []

    def send_done(self, data: bytes) -> None:
        self.to_coordinator(data)

    def send_exchange(self, data: bytes) -> None:
        self.peer.on_exchange(data)

    def publish_failures(self) -> int:
        return 0

    def error(self, text: str) -> None:
        self.errors.append(text)


class Bus:
    """The coordinator's transport: every payload to both roles, their replies back."""

    def __init__(self) -> None:
        self.receiver: Callable[[bytes], None] = lambda data: None
        self.roles = []

    def send(self, data: bytes) -> None:
        for role in self.roles:
            role.on_coupling(data)

    def connected(self, peers: int) -> bool:
        return len(self.roles) >= peers

    def alive(self) -> bool:
        return True

    def node_names(self) -> Set[str]:
        return set()


def split_in_memory(cell, seed: int):
    """Return (coordinator role, micro role, macro role) wired by bytes only."""
    bus = Bus()
    coordinator = CoordinatorRole(cell, seed=seed, transport=bus)
    micro, macro = MicroRole(cell, seed=seed), MacroRole(cell, seed=seed, check_balance=True)
    links = {r: Link(lambda data: bus.receiver(data)) for r in (Role.MICRO, Role.MACRO)}
    links[Role.MICRO].peer, links[Role.MACRO].peer = macro, micro
    micro.serve(links[Role.MICRO])
    macro.serve(links[Role.MACRO])
    bus.roles = [micro, macro]
    return coordinator, micro, macro


class Frames:
    def __init__(self) -> None:
        self.seen: List[Dict[str, bytes]] = []

    def on_frame(self, frame) -> None:
        self.seen.append({topic: bytes(data) for topic, _, data in frame.messages()})


def test_roles_hold_their_own_parts() -> None:
    cell = mid_macro_cell()
    coordinator, micro, macro = split_in_memory(cell, 2)
    assert coordinator.twin.stages == [coordinator.remote]
    assert isinstance(coordinator.remote, RemoteStage)
    assert micro.stage.macro_barriers is micro.side.barriers and micro.exchanges
    assert macro.side.coupling.check and macro.exchanges
    plain_micro, plain_macro = MicroRole(load_cell(), seed=2), MacroRole(load_cell(), seed=2)
    assert plain_micro.side is None and plain_micro.stage.macro_barriers is None
    assert plain_macro.side is None and not plain_macro.exchanges
    assert 'balance_residual' in macro.counters()
    assert not any(k.startswith('balance_') for k in micro.counters())
    assert isinstance(build_scale_role(Role.MACRO, cell, seed=1), MacroRole)
    with pytest.raises(ValueError, match='coordinator is no scale role'):
        build_scale_role(Role.COORDINATOR, cell, seed=1)
    assert Layout('split') is Layout.SPLIT and Layout.COMPOSED == 'composed'
    assert (int(Role.MICRO), int(Role.MACRO)) == (1, 2)  # the role bytes on the wire


def test_reset_restarts_a_role_and_forgets_remote_barriers() -> None:
    micro = MicroRole(mid_macro_cell(), seed=2)
    micro.side.barriers.load([(0, True, 3)], [(0, True, 0.5)])
    assert micro.stage.barrier_blocked()[0]
    micro.reset(micro.cell, 9)
    assert micro.side.barriers.barriers == []
    assert not micro.stage.barrier_blocked()[0]


def test_split_in_memory_equals_composed_bit_for_bit() -> None:
    cell = mid_macro_cell()
    composed = build_twin(cell, seed=3, check_balance=True)
    c_frames, s_frames = Frames(), Frames()
    c_out = TwinOutput([MicroOutput(composed.micro), MacroOutput(composed.macro)])
    c_out.subscribe(c_frames)
    composed.twin.step_listeners.append(c_out.on_step)
    coordinator, micro, macro = split_in_memory(cell, 3)
    micro.output.subscribe(s_frames)
    macro.output.subscribe(s_frames)
    request = check_spawn(cell, cell.part_types[0].name, [0.3], [0.0], [])
    assert list(composed.spawn(request)) == list(coordinator.spawn(request))
    with pytest.raises(ValueError, match='nothing placed'):
        coordinator.spawn(request)  # the same pose again: the micro role's reason
    for twin in (composed.twin, coordinator.twin):
        twin.commands.submit_belt('main', 0.8)
    composed.step(1500)
    coordinator.twin.step(1500)
    assert coordinator.remote.holds_part(0) == composed.holds_part(0)
    assert not coordinator.remote.holds_part(10 ** 6)
    for twin in (composed.twin, coordinator.twin):
        twin.reset(seed=5)
        twin.step(700)
    assert micro.stage.sim.state_bytes() == composed.micro.sim.state_bytes()
    for a, b in zip(macro.stage.grids, composed.macro.grids):
        assert a.density.tobytes() == b.density.tobytes()
    merged = [{**a, **b} for a, b in zip(s_frames.seen[0::2], s_frames.seen[1::2])]
    assert len(merged) == len(c_frames.seen) == 2200
    assert merged == c_frames.seen
    counters = coordinator.remote.counters()
    assert counters['micro_entered'] == composed.micro_counters()['entered']
    assert counters['macro_balance_residual'] == composed.macro_counters()['balance_residual']
    assert not micro.link.errors and not macro.link.errors
