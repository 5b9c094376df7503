"""What every scale needs for one step, and its byte form for the split (multi-process) layout.

The coordinator builds one :class:`StepInput` per step. Composed in one process, the stages get
the object itself; split over processes, they get :meth:`StepInput.pack` bytes over a ROS topic
and :meth:`StepInput.unpack` them. Both carry the same float64 values, which is what keeps the
two layouts bit-identical.
"""

from dataclasses import dataclass, field
import struct

import numpy as np

_HEADER = struct.Struct('<QqIII')  # step, time_ns, belts, actuators, spawned parts


def _empty(dtype: type) -> np.ndarray:
    return np.zeros(0, dtype=dtype)


@dataclass
class StepInput:
    """Inputs of step ``step`` (the state after it is stamped ``time_ns``).

    :param belt_speed: actual speed of every belt during the step [m/s].
    :param actuator_position: actual position of every actuator at the end of the step.
    :param spawn_type: part type index of each part to place before the step.
    :param spawn_x: [m]. :param spawn_y: [m]. :param spawn_yaw: [rad].
    """

    step: int
    time_ns: int
    belt_speed: np.ndarray
    actuator_position: np.ndarray
    spawn_type: np.ndarray = field(default_factory=lambda: _empty(np.uint16))
    spawn_x: np.ndarray = field(default_factory=lambda: _empty(np.float64))
    spawn_y: np.ndarray = field(default_factory=lambda: _empty(np.float64))
    spawn_yaw: np.ndarray = field(default_factory=lambda: _empty(np.float64))

    def pack(self) -> bytes:
        """Return the little-endian byte form."""
        n = self.spawn_type.size
        parts = [_HEADER.pack(self.step, self.time_ns, self.belt_speed.size,
                              self.actuator_position.size, n),
                 self.belt_speed.astype('<f8').tobytes(),
                 self.actuator_position.astype('<f8').tobytes()]
        if n:
            parts += [self.spawn_x.astype('<f8').tobytes(), self.spawn_y.astype('<f8').tobytes(),
                      self.spawn_yaw.astype('<f8').tobytes(),
                      self.spawn_type.astype('<u2').tobytes()]
        return b''.join(parts)

    @classmethod
    def unpack(cls, data: bytes) -> 'StepInput':
        """Rebuild a :class:`StepInput` from :meth:`pack` bytes."""
        step, time_ns, nb, na, n = _HEADER.unpack_from(data, 0)
        offset = _HEADER.size

        def take(count: int, dtype: str) -> np.ndarray:
            nonlocal offset
            array = np.frombuffer(data, dtype=dtype, count=count, offset=offset)
            offset += array.nbytes
            return array.astype(dtype[1:] if dtype[0] == '<' else dtype)

        belt_speed, actuator_position = take(nb, '<f8'), take(na, '<f8')
        if not n:
            return cls(step, time_ns, belt_speed, actuator_position)
        x, y, yaw = take(n, '<f8'), take(n, '<f8'), take(n, '<f8')
        return cls(step, time_ns, belt_speed, actuator_position, take(n, '<u2'), x, y, yaw)
