"""What every scale needs for one step.

The coordinator builds one :class:`StepInput` per step. Composed in one process, the stages get
the object itself; split over processes, they get its bytes
(:func:`conveyor_twin.split.protocol.pack_step_input`) over a ROS topic. Both carry the same
float64 values, which is what keeps the two layouts bit-identical.
"""

from dataclasses import dataclass
from typing import Tuple

import numpy as np

from conveyor_twin.faults.book import FaultEvent


@dataclass
class StepInput:
    """Inputs of step ``step`` (the state after it is stamped ``time_ns``).

    :param belt_speed: actual speed of every belt during the step [m/s].
    :param actuator_position: actual position of every actuator at the end of the step
        [m or rad].
    :param faults: faults injected or cleared at this step (usually none), in order.
    """

    step: int
    time_ns: int
    belt_speed: np.ndarray
    actuator_position: np.ndarray
    faults: Tuple[FaultEvent, ...] = ()
