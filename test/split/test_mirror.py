"""The split-layout hand-over in memory: a micro mirror and bytes both ways, bit-identical to
the composed coupling (:mod:`conveyor_twin.split.mirror`)."""

from typing import Dict, List

import numpy as np
import pytest
import yaml

from conveyor_twin.cell.loader import cell_from_mapping, default_cell_text
from conveyor_twin.coord.assembly import build_twin
from conveyor_twin.coord.twin import Twin
from conveyor_twin.coupling.scale import ScaleCoupling
from conveyor_twin.micro.sim import MicroSim
from conveyor_twin.split.mirror import has_coupling, MirrorSim
from conveyor_twin.split.protocol import encode_state, load_state
from conveyor_twin.split.roles import MacroRole, MicroRole
from test.coupling.deflector_scenario import deflector_cell

COMPARE_EVERY = 250


class Pair:
    """A composed twin and a split pair in memory (micro half, macro half on a mirror) fed the
    same step inputs; the halves exchange only bytes."""

    def __init__(self, cell, seed: int = 1) -> None:
        self.cell = cell
        composed = build_twin(cell, seed=seed)
        self.c_micro, self.c_macro = composed.micro, composed.macro
        self.composed = composed.twin
        self.c_coupling = self.composed.stages[-1]
        assert isinstance(self.c_coupling, ScaleCoupling)
        self.c_coupling.check = True
        self.coordinator = Twin(cell, seed=seed)  # inputs only: no stages
        micro_role = MicroRole(cell, seed=seed)
        macro_role = MacroRole(cell, seed=seed, check_balance=True)
        self.s_micro, self.s_macro = micro_role.stage, macro_role.stage
        self.micro_side = micro_role.side
        self.macro_side = macro_role.side
        self.bytes_sent = 0

    @property
    def s_coupling(self) -> ScaleCoupling:
        return self.macro_side.coupling

    def step(self, n: int) -> None:
        for _ in range(n):
            self.composed.step()
            inp = self.coordinator.step()
            self.s_micro.advance(inp)
            state = self.micro_side.state_bytes()
            self.s_macro.advance(inp)
            reply = self.macro_side.couple(inp, state)
            self.micro_side.apply(reply)
            self.bytes_sent += len(state) + len(reply)

    def spawn(self, *args) -> None:
        assert (self.c_micro.spawn(*args) == self.s_micro.spawn(*args)).all()

    def force_tiles(self, zone: str, macro: np.ndarray) -> None:
        self.c_coupling.force_tiles(zone, macro)
        self.micro_side.apply(self.macro_side.force_tiles(
            zone, macro, self.micro_side.state_bytes()))

    def reset(self, seed: int) -> None:
        self.composed.reset(seed=seed)
        self.coordinator.reset(seed=seed)
        for stage in (self.s_micro, self.s_macro):
            stage.reset(self.cell, seed)
        self.micro_side.reset()
        self.macro_side.reset(self.cell, seed)

    def assert_identical(self) -> None:
        assert self.s_micro.sim.state_bytes() == self.c_micro.sim.state_bytes()
        for a, b in zip(self.s_macro.grids, self.c_macro.grids):
            assert a.density.tobytes() == b.density.tobytes()
        assert self.s_coupling.state_bytes() == self.c_coupling.state_bytes()
        assert self.s_coupling.ledger() == self.c_coupling.ledger()
        assert self.s_macro.counters() == self.c_macro.counters()
        for name in ('barrier_blocked', 'barrier_edge_count'):
            a, b = getattr(self.s_micro, name)(), getattr(self.c_micro, name)()
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes(), name
        for a, b in zip(self.s_micro.edges(), self.c_micro.edges()):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
        # the mirror after the coupling holds what the micro process holds after replaying
        assert encode_state(self.macro_side.mirror.sim) == self.micro_side.state_bytes()

    def run(self, steps: int, every: int = COMPARE_EVERY) -> List[Dict[str, float]]:
        seen = []
        for _ in range(steps // every):
            self.step(every)
            self.assert_identical()
            seen.append(self.c_coupling.ledger())
        return seen


def _cell(zones, rate: float, speed: float = 0.5):
    d = yaml.safe_load(default_cell_text())
    d['sources'][0]['rate'] = rate
    d['belts'][0]['speed'] = speed
    d['zones'] = zones
    return cell_from_mapping(d)


def test_state_bytes_round_trip_into_a_mirror() -> None:
    cell = _cell([{'name': 'mid', 'policy': 'macro', 'region': [1.5, -0.25, 2.5, 0.25]}],
                 rate=300.0)
    sim = MicroSim(cell, seed=3)
    sim.step(400)
    mirror = MirrorSim(cell, seed=3)
    mirror.load(encode_state(sim))
    assert encode_state(mirror) == encode_state(sim) and mirror.n == sim.n > 50
    assert mirror.take_edits() == b'\x00\x00\x00\x00'  # nothing edited
    with pytest.raises(ValueError, match='does not match'):
        load_state(MicroSim(cell, seed=3), encode_state(sim) + b'\x00')


def test_auto_zone_with_jam_and_tile_switches_is_bit_identical_split() -> None:
    # (a) the deflector jam on the default cell (auto zone, 500 parts/s): tiles turn macro as
    # the jam grows and parts are released from the density; compared every 250 steps
    cell = deflector_cell('auto')
    assert has_coupling(cell)
    pair = Pair(cell)
    pair.run(7000)
    c = pair.c_coupling
    assert c.regions[0].tiles.switches > 0, 'the test should switch tiles'
    assert c.captured > 200 and c.released > 50, (c.captured, c.released)
    assert pair.c_micro.sim.n > 500
    # spawns between steps and forced tiles (both directions) stay identical too
    pair.spawn(0, np.array([0.3]), np.array([0.0]), np.zeros(1))
    tiles = c.regions[0].tiles
    for k in range(2):
        pair.force_tiles('belt', np.ones_like(tiles.macro) if k == 0
                         else np.zeros_like(tiles.macro))
        pair.assert_identical()
        pair.step(50)
        pair.assert_identical()
    assert pair.s_coupling.max_residual <= 1e-9


def test_macro_zone_with_a_light_barrier_is_bit_identical_split() -> None:
    # (b) a macro zone holding lb_infeed (x = 2.0): its edges come from the density, the other
    # barrier's from the micro parts; sinks and reset included
    zones = [{'name': 'up', 'policy': 'micro', 'region': [0.0, -0.25, 1.5, 0.25]},
             {'name': 'mid', 'policy': 'macro', 'region': [1.5, -0.25, 2.5, 0.25]},
             {'name': 'end', 'policy': 'macro', 'region': [5.0, -0.25, 6.0, 0.25]}]
    cell = _cell(zones, rate=150.0, speed=1.5)  # parts reach the exit sink
    pair = Pair(cell)
    edges = 0
    for _ in range(24):
        pair.step(250)
        pair.assert_identical()
        edges += int((pair.c_micro.edges()[0] == 0).sum())
    assert pair.c_coupling.barriers and pair.c_micro.barrier_edge_count()[0] > 4
    assert pair.c_coupling.left_macro > 0  # parts left through the sink in a macro zone
    pair.reset(seed=5)
    pair.assert_identical()
    pair.run(1000)
