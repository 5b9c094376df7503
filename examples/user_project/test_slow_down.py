"""Tests of slow_down.py, written against conveyor_twin.testing only."""

from pathlib import Path
import sys

from conveyor_twin.testing import quiet_cell

from slow_down import SlowDown

CONTROLLER = Path(__file__).with_name('slow_down.py')


def test_belt_runs_slowly_while_a_part_blocks_the_barrier(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), seed=1, chunk=5)
    twin.add_node(SlowDown(context=twin.context))
    twin.spawn('spacer', [1.8], [0.0])
    twin.step_until(lambda: twin.barrier('lb_infeed').blocked, max_steps=1000,
                    what='the part blocks lb_infeed')
    twin.step(10)
    assert twin.belt('main').commanded_speed == 0.2
    twin.step_until(lambda: not twin.barrier('lb_infeed').blocked, max_steps=3000,
                    what='the part clears lb_infeed')
    twin.step(10)
    assert twin.belt('main').commanded_speed == 0.5
    assert [r.value for r in twin.command_log()] == [0.2, 0.5]  # nobody else's commands
    assert [(r.sender, r.sequence) for r in twin.command_log()] == [('slow_down', 1),
                                                                    ('slow_down', 2)]


def test_controller_as_its_own_process(conveyor_twin_factory):
    twin = conveyor_twin_factory(quiet_cell(), seed=1, chunk=5)
    twin.start_controller([sys.executable, str(CONTROLLER), '--ros-args', '-p', 'slow:=0.1'])
    twin.wait_for_node('slow_down', subscribes=['light_barriers'], publishes=['belt_command'])
    twin.spawn('spacer', [1.8], [0.0])
    twin.step_until(lambda: twin.barrier('lb_infeed').blocked, max_steps=1000)
    twin.wait_until(lambda: len(twin.command_log()) == 1, what='the controller slows the belt')
    twin.step(5)
    assert twin.belt('main').commanded_speed == 0.1


def test_the_default_cell_feeds_parts_past_the_barrier(conveyor_twin):
    conveyor_twin.step_until(lambda: conveyor_twin.edges(name='lb_infeed'), max_steps=5000)
    assert len(conveyor_twin.parts().id) > 0
    assert conveyor_twin.set_belt('main', 0.3).accepted
    conveyor_twin.step(1)
    assert conveyor_twin.belt('main').commanded_speed == 0.3
    assert [r.value for r in conveyor_twin.command_log()] == [0.3]  # nobody else's commands
