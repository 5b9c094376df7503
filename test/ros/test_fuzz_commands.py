"""Fuzzing the twin's command topics and services on a lockstep twin.

Seeded random ``belt_command``/``actuator_command`` messages (known and unknown names, empty,
very long, NUL-containing and non-ASCII strings; NaN, +-inf, huge and in-range values),
``spawn_parts`` calls (unknown part types, ragged and huge arrays, values anywhere), ``reset``
calls (missing, NUL-containing, very long and directory paths, any seed) and ``step`` calls
go to a composed lockstep twin. After every input the twin must still answer and step, its
belt and actuator targets must be finite and within their ranges (an invalid command is never
applied), every part must lie finite inside the cell, and no traceback may have been printed.

:data:`FAST_INPUTS` inputs run by default; the slow-marked test runs :data:`SLOW_INPUTS`.
"""

import math
import random

from conveyor_twin_msgs.msg import ActuatorCommand, BeltCommand
from conveyor_twin_msgs.srv import Reset, SpawnParts, Step
import numpy as np
import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.ros.compose import ComposedTwin
from conveyor_twin.testing import quiet_cell
from conveyor_twin.testing.driver import Driver
from conveyor_twin.wire import cdr

pytestmark = pytest.mark.ros
SEED = 20261123
FAST_INPUTS = 60
SLOW_INPUTS = 600
NAMES = ('main', 'pusher', 'stopper', 'spacer', '', 'MAIN', 'main\x00', 'a\x00b', 'x' * 100_000,
         'ü' * 1000, 'main ', '\n', '../..')
VALUES = (0.0, 0.1, -0.1, 0.5, 1.0, 2.0, -2.0, 2.0000001, math.nan, math.inf, -math.inf,
          1e308, -1e308, 5e-324, 1e9, 0.05, 0.3)
PATHS = ('', 'missing.yaml', 'a\x00b.yaml', 'x' * 5000, '/', '/dev/null', '/proc/self/status',
         '\x00')


class Harness(Driver):
    """A composed lockstep twin (its cores inspected after every input) and a driver."""

    def __init__(self, context, *, seed: int = 7, cell=None) -> None:
        self.twin = ComposedTwin(cell or load_cell(), seed=seed, mode=TimeMode.LOCKSTEP,
                                 context=context, markers_rate=0.0)
        self.twin.start()
        super().__init__(context)
        assert self.wait_connected(), 'twin not discovered'

    def close(self) -> None:
        super().close()
        self.twin.stop()


def value(rng: random.Random) -> float:
    return rng.choice(VALUES) if rng.random() < 0.7 else rng.uniform(-10.0, 10.0)


def name(rng: random.Random) -> str:
    return rng.choice(NAMES)


def array(rng: random.Random, n: int) -> list:
    if rng.random() < 0.5:
        return [value(rng) for _ in range(n)]
    return np.random.default_rng(rng.randrange(2 ** 32)).uniform(-1.0, 7.0, n).tolist()


@pytest.fixture
def harness(ros_context):
    h = Harness(ros_context, cell=quiet_cell())
    yield h
    h.close()


def check_state(h: Harness, label: str) -> None:
    """The twin's applied targets and its parts are valid."""
    twin = h.twin.twin
    cell = twin.cell
    belts = twin.actuation.belt_target
    assert np.isfinite(belts).all(), (label, belts)
    assert all(abs(v) <= b.max_speed for v, b in zip(belts, cell.belts)), (label, belts)
    actuators = twin.actuation.actuator_target
    assert np.isfinite(actuators).all(), (label, actuators)
    assert all(a.position_range[0] <= v <= a.position_range[1]
               for v, a in zip(actuators, cell.actuators)), (label, actuators)
    parts = cdr.decode_part_states(h.probe.received['parts'][-1])
    assert np.isfinite(parts.x).all() and np.isfinite(parts.y).all(), label
    assert h.twin.runner.error is None, (label, h.twin.runner.error)


def send(h: Harness, rng: random.Random, tally: dict) -> str:
    """Send one random input; return what it was."""
    kind = rng.choice(('belt', 'belt', 'actuator', 'actuator', 'spawn', 'spawn', 'reset', 'step'))
    tally[kind] = tally.get(kind, 0) + 1
    if kind in ('belt', 'actuator'):
        msg = (BeltCommand(belt=name(rng), speed=value(rng)) if kind == 'belt'
               else ActuatorCommand(actuator=name(rng), position=value(rng)))
        h.command(msg)
        return f'{kind} {msg.belt if kind == "belt" else msg.actuator!r:.40} ' \
               f'{msg.speed if kind == "belt" else msg.position!r}'
    if kind == 'spawn':
        n = rng.choice((0, 1, 1, 2, 5, 50, 20_000))
        ny = n if rng.random() < 0.85 else rng.choice((0, n + 1))
        request = SpawnParts.Request(part_type=name(rng), x=array(rng, n), y=array(rng, ny),
                                     yaw=array(rng, rng.choice((0, n, n))))
        response = h.call(h.spawn_client, request)
        assert response.success or response.message, 'a refusal without a reason'
        assert response.success or not list(response.id)
        return f'spawn {request.part_type!r:.40} x[{n}] y[{ny}]: {response.message[:80]}'
    if kind == 'reset':
        request = Reset.Request(cell_file=rng.choice(PATHS),
                                seed=rng.choice((0, 1, 2 ** 63, 2 ** 64 - 1, rng.randrange(99))))
        response = h.call(h.reset_client, request)
        assert response.success or response.message, 'a refusal without a reason'
        return f'reset {request.cell_file!r:.40} seed {request.seed}: {response.message[:80]}'
    response = h.call(h.step_client, Step.Request(steps=rng.choice((0, 1, 3))))
    return f'step: {response}'


def fuzz(h: Harness, count: int, seed: int) -> dict:
    rng = random.Random(seed)
    tally: dict = {}
    h.step(1)
    for i in range(count):
        label = f'input {i} (seed {seed}): ' + send(h, rng, tally)
        h.step(1)                      # the twin keeps stepping, every stream delivers
        check_state(h, label)
    return tally


def test_fuzzed_commands_and_calls_are_refused_or_valid(harness, capfd):
    tally = fuzz(harness, FAST_INPUTS, SEED)
    assert 'Traceback' not in capfd.readouterr().err
    with capfd.disabled():
        print(f'command fuzz: {FAST_INPUTS} inputs {tally}, rejected commands '
              f'{harness.twin.twin.commands.rejected_total}')
    assert harness.twin.twin.commands.rejected_total > 0


@pytest.mark.slow
def test_fuzzed_commands_and_calls_many(harness, capfd):
    tally = fuzz(harness, SLOW_INPUTS, SEED + 1)
    assert 'Traceback' not in capfd.readouterr().err
    with capfd.disabled():
        print(f'command fuzz: {SLOW_INPUTS} inputs {tally}, rejected commands '
              f'{harness.twin.twin.commands.rejected_total}')
