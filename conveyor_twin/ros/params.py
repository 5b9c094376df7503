"""Node parameters shared by the three nodes, declared with descriptions and read once."""

from dataclasses import dataclass
from typing import List

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.parameter import Parameter

from conveyor_twin import __version__
from conveyor_twin.contract import DIAGNOSTICS_PERIOD_STEPS  # noqa: F401 - used by the nodes
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
    :param foxglove: ``[HOST:]PORT`` of a live Foxglove view the coordinator serves; empty:
        none.
    :param scenario: fault scenario file the coordinator arms; empty: none.
    """

    cell_file: str
    seed: int
    mode: TimeMode
    markers_rate: float
    duration: float
    foxglove: str = ''
    scenario: str = ''


def declare_twin_parameters(node: Node, *, step_s: float = 1e-3) -> TwinParameters:
    """Declare the twin's parameters on ``node`` and return their values.

    Every node of the twin (``scale_coordinator``, ``micro_simulator``, ``macro_simulator``)
    declares them, so ``ros2 param list/describe/get`` show the run's knobs on each. They are
    read once at start (read only); ``namespace``, ``stream_rate``, ``diagnostics_rate`` and
    ``version`` only report (the namespace is set by ``--namespace`` or ``-r __ns:=...``, the
    rates follow the cell's step).

    :param step_s: the cell's step [s], for the reported rates.
    """
    def declare(name: str, default, description: str, **kwargs):
        return node.declare_parameter(
            name, default, ParameterDescriptor(description=description, read_only=True),
            **kwargs).value

    cell_file = declare('cell_file', '', 'cell YAML file; empty: the embedded default cell')
    seed = declare('seed', -1, 'random seed of the run; negative: the seed in the cell file')
    mode = declare('mode', 'realtime', 'time mode: realtime, fast or lockstep')
    markers_rate = declare('markers_rate', DEFAULT_MARKERS_RATE,
                           'rate of visualization markers on `markers` [Hz]; 0 disables them')
    duration = declare('duration', 0.0,
                       'stop after this much simulated time [s]; 0 runs until shutdown')
    foxglove = declare('foxglove', '',
                       'address [HOST:]PORT of the live Foxglove WebSocket view the coordinator '
                       'serves (host 127.0.0.1 by default); empty: none')
    scenario = declare('scenario', '',
                       'fault scenario YAML the coordinator arms at start (docs/faults.md); '
                       'empty: none')
    declare('namespace', node.get_namespace(),
            'namespace of the twin\'s relative topics and services (set with --namespace or '
            '-r __ns:=...)', ignore_override=True)
    declare('stream_rate', 1.0 / step_s,
            'rate of the every-step streams and /clock in sim time [Hz] (1 / cell step)',
            ignore_override=True)
    declare('diagnostics_rate', 1.0 / (DIAGNOSTICS_PERIOD_STEPS * step_s),
            'rate of `diagnostics` in sim time [Hz]', ignore_override=True)
    declare('version', __version__, 'version of conveyor_twin', ignore_override=True)
    try:
        time_mode = TimeMode(mode)
    except ValueError:
        raise ValueError(f"parameter 'mode' is {mode!r}; expected one of "
                         + ', '.join(m.value for m in TimeMode)) from None
    if markers_rate < 0.0 or duration < 0.0:
        raise ValueError('parameters markers_rate and duration must not be negative')
    return TwinParameters(cell_file, int(seed), time_mode, float(markers_rate), float(duration),
                          str(foxglove), str(scenario))


def parameter_overrides(*, cell_file: str, seed: int, mode: TimeMode, markers_rate: float,
                        duration: float, foxglove: str = '',
                        scenario: str = '') -> List[Parameter]:
    """Return the parameter values of a composed run, for the nodes built in this process."""
    return [Parameter('cell_file', value=cell_file), Parameter('seed', value=int(seed)),
            Parameter('mode', value=TimeMode(mode).value),
            Parameter('markers_rate', value=float(markers_rate)),
            Parameter('duration', value=float(duration)),
            Parameter('foxglove', value=str(foxglove)),
            Parameter('scenario', value=str(scenario))]
