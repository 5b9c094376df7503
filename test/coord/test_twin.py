"""The coordinator core: step schedule, command timing, modes."""

from typing import List

import numpy as np

from conveyor_twin.cell import load_cell
from conveyor_twin.split.protocol import pack_step_input, unpack_step_input
from conveyor_twin.coord.runner import Runner
from conveyor_twin.coord.step_input import StepInput
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.coord.twin import Twin


class RecordingStage:
    """A stage that remembers every input it was given."""

    def __init__(self) -> None:
        self.inputs: List[StepInput] = []
        self.resets = 0

    def advance(self, inp: StepInput) -> None:
        self.inputs.append(inp)

    def reset(self, cell, seed) -> None:
        self.resets += 1
        self.inputs.clear()


def test_commands_take_effect_at_the_next_step_boundary() -> None:
    stage = RecordingStage()
    twin = Twin(load_cell(), seed=3, stages=[stage])
    twin.step(2)
    twin.commands.submit_belt('main', 0.0)
    seen = []
    twin.step_listeners.append(lambda inp, cmds: seen.append((inp.step, cmds)))
    twin.step(1)
    assert seen[0][0] == 3 and [(c.name, c.step) for c in seen[0][1]] == [('main', 3)]
    speeds = [inp.belt_speed[0] for inp in stage.inputs]
    assert speeds[:2] == [0.5, 0.5]
    assert speeds[2] == 0.5 - 2.0 * 1e-3  # ramps down at the belt's acceleration from step 3
    assert [inp.time_ns for inp in stage.inputs] == [1_000_000, 2_000_000, 3_000_000]


def test_step_input_round_trips_exactly() -> None:
    inp = StepInput(7, 7_000_000, np.array([0.1, -0.3]), np.array([np.pi, 1e-300]))
    back = unpack_step_input(pack_step_input(inp))
    assert back.step == 7 and back.time_ns == 7_000_000
    assert back.belt_speed.tobytes() == inp.belt_speed.tobytes()
    assert back.actuator_position.tobytes() == inp.actuator_position.tobytes()


def test_reset_restarts_time_and_stages() -> None:
    stage = RecordingStage()
    twin = Twin(load_cell(), seed=3, stages=[stage])
    twin.commands.submit_belt('main', 1.0)
    twin.step(10)
    twin.reset(seed=9)
    assert twin.step_index == 0 and twin.seed == 9 and stage.resets == 1
    assert twin.actuation.belt_target[0] == 0.5


def test_fast_mode_runs_exactly_max_steps() -> None:
    stage = RecordingStage()
    twin = Twin(load_cell(), seed=0, stages=[stage])
    runner = Runner(twin, TimeMode.FAST, max_steps=500)
    runner.start()
    assert runner.wait(60.0)
    assert runner.error is None
    assert twin.step_index == 500 and [i.step for i in stage.inputs] == list(range(1, 501))
    assert runner.stats.count == 500


def test_lockstep_advances_only_when_asked() -> None:
    twin = Twin(load_cell(), seed=0, stages=[RecordingStage()])
    runner = Runner(twin, TimeMode.LOCKSTEP)
    runner.start()
    assert not runner.running and twin.step_index == 0
    runner.step(25)
    assert twin.step_index == 25


def test_realtime_mode_keeps_pace() -> None:
    twin = Twin(load_cell(), seed=0, stages=[RecordingStage()])
    runner = Runner(twin, TimeMode.REALTIME, max_steps=200)
    runner.start()
    assert runner.wait(30.0)
    # 200 steps of 1 ms cannot finish before 200 ms of wall time: the pacer waited
    assert runner.wall_end - runner.wall_start >= 0.199
    assert twin.step_index == 200


def test_a_failing_stage_stops_the_thread_and_is_reported() -> None:
    class Broken(RecordingStage):
        def advance(self, inp: StepInput) -> None:
            if inp.step == 5:
                raise RuntimeError('diverged')

    errors = []
    twin = Twin(load_cell(), seed=0, stages=[Broken()])
    runner = Runner(twin, TimeMode.FAST, max_steps=100, on_error=errors.append)
    runner.start()
    assert runner.wait(30.0)
    assert isinstance(runner.error, RuntimeError) and errors == [runner.error]
    assert twin.step_index == 4
