"""Errors of the micro simulator."""


class MicroError(RuntimeError):
    """Base of the micro simulator's errors."""


class SpawnOverlapError(MicroError, ValueError):
    """An explicit placement overlaps a part, an obstacle or a solid actuator (nothing placed)."""


class CapacityError(MicroError):
    """The preallocated part capacity is exhausted."""


class SpawnBoundsError(MicroError, ValueError):
    """An explicit placement lies outside the cell's extent (nothing placed)."""
