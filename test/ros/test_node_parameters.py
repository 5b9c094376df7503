"""Node parameters: declared with descriptions on the twin's real nodes, listed over ROS."""

import pytest

from conveyor_twin.cell import load_cell
from conveyor_twin.coord.timing import TimeMode
from conveyor_twin.ros.compose import ComposedTwin
from conveyor_twin.testing import Driver

pytestmark = pytest.mark.ros
NODES = ('/scale_coordinator', '/micro_simulator', '/macro_simulator')
DECLARED = {'cell_file', 'seed', 'mode', 'markers_rate', 'duration', 'namespace',
            'stream_rate', 'diagnostics_rate', 'foxglove'}


def check_parameters(driver: Driver, node: str, *, seed: int, mode: str,
                     markers_rate: float, namespace: str = '/') -> None:
    """Assert a node of the twin lists its parameters with values and descriptions."""
    params = driver.parameters(node)
    assert DECLARED <= set(params), (node, sorted(params))
    for name in DECLARED:
        value, description, read_only = params[name]
        assert description, (node, name)
        assert read_only, (node, name)
    assert params['seed'][0] == seed
    assert params['mode'][0] == mode
    assert params['markers_rate'][0] == markers_rate
    assert params['namespace'][0] == namespace
    assert params['stream_rate'][0] == pytest.approx(1000.0)
    assert params['diagnostics_rate'][0] == pytest.approx(1.0)
    assert params['foxglove'][0] == ''  # no live view unless asked for


def test_composed_nodes_declare_their_parameters(ros_context):
    twin = ComposedTwin(load_cell(), seed=5, mode=TimeMode.LOCKSTEP, context=ros_context,
                        markers_rate=12.5, max_steps=3000)
    twin.start()
    driver = Driver(ros_context, name='param_probe')
    try:
        for node in NODES:
            check_parameters(driver, node, seed=5, mode='lockstep', markers_rate=12.5)
        assert driver.parameters('/scale_coordinator')['duration'][0] == pytest.approx(3.0)
        assert driver.parameters('/micro_simulator')['cell_file'][0] == ''
    finally:
        driver.close()
        twin.stop()
