"""Node parameters shared by the three nodes, declared with descriptions and read once."""

from dataclasses import dataclass

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

from conveyor_twin.coord.timing import TimeMode

DEFAULT_MARKERS_RATE = 30.0  # Hz, viewer rate of `markers`


@dataclass(frozen=True)
class TwinParameters:
    """The runtime knobs of a node (the cell file holds everything physical).

    :param cell_file: cell YAML; empty means the embedded default cell.
    :param seed: random seed; negative means the cell's own seed.
    :param mode: realtime, fast or lockstep (coordinator only).
    :param markers_rate: MarkerArray rate [Hz]; 0 disables markers.
    :param duration: stop after this much simulated time [s]; 0 runs until shut down.
    """

    cell_file: str
    seed: int
    mode: TimeMode
    markers_rate: float
    duration: float


def declare_twin_parameters(node: Node) -> TwinParameters:
    """Declare the twin's parameters on ``node`` and return their values."""
    def declare(name: str, default, description: str):
        return node.declare_parameter(
            name, default, ParameterDescriptor(description=description)).value

    cell_file = declare('cell_file', '', 'cell YAML file; empty: the embedded default cell')
    seed = declare('seed', -1, 'random seed of the run; negative: the seed in the cell file')
    mode = declare('mode', 'realtime', 'time mode: realtime, fast or lockstep')
    markers_rate = declare('markers_rate', DEFAULT_MARKERS_RATE,
                           'rate of visualization markers on `markers` [Hz]; 0 disables them')
    duration = declare('duration', 0.0,
                       'stop after this much simulated time [s]; 0 runs until shutdown')
    try:
        time_mode = TimeMode(mode)
    except ValueError:
        raise ValueError(f"parameter 'mode' is {mode!r}; expected one of "
                         + ', '.join(m.value for m in TimeMode)) from None
    if markers_rate < 0.0 or duration < 0.0:
        raise ValueError('parameters markers_rate and duration must not be negative')
    return TwinParameters(cell_file, int(seed), time_mode, float(markers_rate), float(duration))
