"""Errors raised while reading a cell description."""

import reprlib
from typing import Any

# values are shown shortened: a deeply nested or huge value still gives a readable message
_REPR = reprlib.Repr()
_REPR.maxlevel = 4
_REPR.maxstring = 80
_REPR.maxother = 80
_REPR.maxlong = 40


class CellError(ValueError):
    """A cell description is invalid; the message names file, key path, value and expectation."""

    def __init__(self, file: str, key_path: str, value: Any, expected: str) -> None:
        self.file = file
        self.key_path = key_path
        self.value = value
        self.expected = expected
        msg = f'{file}: {key_path}: got {_REPR.repr(value)}; expected {expected}'
        super().__init__(msg)
