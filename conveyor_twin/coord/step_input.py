"""What every scale needs for one step, and its byte form for the split (multi-process) layout.

The coordinator builds one :class:`StepInput` per step. Composed in one process, the stages get
the object itself; split over processes, they get :meth:`StepInput.pack` bytes over a ROS topic
and :meth:`StepInput.unpack` them. Both carry the same float64 values, which is what keeps the
two layouts bit-identical.
"""

from dataclasses import dataclass
import struct

import numpy as np

_HEADER = struct.Struct('<QqII')  # step, time_ns, number of belts, number of actuators


@dataclass
class StepInput:
    """Inputs of step ``step`` (the state after it is stamped ``time_ns``).

    :param belt_speed: actual speed of every belt during the step [m/s].
    :param actuator_position: actual position of every actuator at the end of the step
        [m or rad].
    """

    step: int
    time_ns: int
    belt_speed: np.ndarray
    actuator_position: np.ndarray

    def pack(self) -> bytes:
        """Return the little-endian byte form."""
        return b''.join((_HEADER.pack(self.step, self.time_ns, self.belt_speed.size,
                                      self.actuator_position.size),
                         self.belt_speed.astype('<f8').tobytes(),
                         self.actuator_position.astype('<f8').tobytes()))

    @classmethod
    def unpack(cls, data: bytes) -> 'StepInput':
        """Rebuild a :class:`StepInput` from :meth:`pack` bytes."""
        step, time_ns, nb, na = _HEADER.unpack_from(data, 0)
        belts = np.frombuffer(data, '<f8', nb, _HEADER.size).astype(np.float64)
        actuators = np.frombuffer(data, '<f8', na, _HEADER.size + 8 * nb).astype(np.float64)
        return cls(step, time_ns, belts, actuators)
