"""Errors raised while reading a plant description."""

from conveyor_twin.cell.errors import CellError


class PlantError(CellError):
    """A plant description is invalid; the message names file, key path, value and expectation.

    A cell file the plant names that is itself invalid raises its own
    :class:`~conveyor_twin.cell.errors.CellError` (naming the cell file).
    """
