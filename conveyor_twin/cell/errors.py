"""Errors raised while reading a cell description."""

from typing import Any


class CellError(ValueError):
    """A cell description is invalid; the message names file, key path, value and expectation."""

    def __init__(self, file: str, key_path: str, value: Any, expected: str) -> None:
        self.file = file
        self.key_path = key_path
        self.value = value
        self.expected = expected
        msg = f'{file}: {key_path}: got {value!r}; expected {expected}'
        super().__init__(msg)
