"""Failures of a plant's threads are never silent: a link's callback, a cell's stepping thread,
the composed plant's stepping thread and the monitor's callback report to their ``Health``
once, with the traceback, and end the run; the monitor's diagnostics then say ERROR."""

from pathlib import Path

import pytest

from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.plant.link import Departures, Transit
from conveyor_twin.plant.loader import load_plant, plant_from_mapping
from conveyor_twin.testing.ros_env import wait_for

RES = Path(__file__).resolve().parents[1] / 'resources' / 'plant'
TIMEOUT = 120.0         # s, a bound for a loaded machine

pytestmark = pytest.mark.ros


def solo():
    """A plant of one cell and no links (it steps without waiting for anyone)."""
    return plant_from_mapping({'plant': {'name': 'solo'},
                               'cells': [{'name': 'only', 'file': 'relay.yaml'}]},
                              str(RES / 'solo.yaml'), RES)


def test_a_failing_link_callback_is_reported_and_ends_the_cells_run(ros_context):
    from conveyor_twin.ros.plant_cell_node import PlantCellNode
    from conveyor_twin.ros.plant_messages import departures_msg
    node = PlantCellNode(load_plant(RES / 'chain.yaml'), 'second', context=ros_context,
                         mode=TimeMode.FAST, end_step=100, streams=False)
    node.start()
    try:
        def batch(first: int) -> Departures:
            part = Transit(first, 1, 7, 7, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            return Departures('first_second', 5, first, 0, [part], run=1)
        callback = node._subs[0].callback       # the entry's: parts of first_second
        callback(departures_msg(batch(0), 0))
        assert node.health.ok
        callback(departures_msg(batch(3), 0))   # part 3 where part 1 is due: a lost batch
        assert wait_for(lambda: not node._threads[-1].is_alive(), TIMEOUT)
        [failure] = node.health.failures
        assert failure.name == "plant cell 'second': link 'first_second' entry"
        assert 'part 3 arrived, 1 expected' in failure.error and 'Traceback' in failure.traceback
        assert isinstance(node.error, ValueError) and node.done.is_set()
    finally:
        node.stop()


def test_a_failing_stepping_thread_is_reported(ros_context):
    from conveyor_twin.ros.plant_cell_node import PlantCellNode
    node = PlantCellNode(solo(), 'only', context=ros_context, mode=TimeMode.FAST,
                         end_step=0, streams=False)
    step = node.core.step

    def failing_step() -> None:
        if node.core.step_index == 20:
            raise RuntimeError('injected')
        step()
    node.core.step = failing_step
    node.start()
    try:
        assert wait_for(node.done.is_set, TIMEOUT)
        [failure] = node.health.failures
        assert failure.name == "plant cell 'only': stepping thread"
        assert "RuntimeError('injected')" == failure.error
        assert node.core.step_index == 20
    finally:
        node.stop()


def test_a_failing_composed_plant_is_reported(ros_context):
    from conveyor_twin.ros.plant_node import ComposedPlant
    plant = ComposedPlant(load_plant(RES / 'chain.yaml'), context=ros_context,
                          mode=TimeMode.FAST, end_step=1000, streams=False)

    def broken(end: int, **kw) -> None:
        raise RuntimeError('injected')
    plant.runner.run_to = broken
    plant.start()
    try:
        assert wait_for(plant.done.is_set, TIMEOUT)
        assert plant.failures() == ["plant stepping thread: RuntimeError('injected')"]
    finally:
        plant.stop()


def test_a_failing_monitor_callback_makes_the_plant_diagnostics_an_error(ros_context):
    from diagnostic_msgs.msg import DiagnosticStatus
    from conveyor_twin.ros.plant_monitor import PlantMonitor
    monitor = PlantMonitor(load_plant(RES / 'chain.yaml'), context=ros_context)
    try:
        monitor._sub.callback(object())        # not a CellProgress
        [failure] = monitor.health.failures
        assert failure.name == 'plant monitor (progress)' and 'AttributeError' in failure.error
        status = monitor.status()
        assert status.level == DiagnosticStatus.ERROR
        assert status.message.startswith('failed: plant monitor (progress): AttributeError')
    finally:
        monitor.destroy()
