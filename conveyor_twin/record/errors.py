"""Errors of the recording package."""


class RecordingError(RuntimeError):
    """A recording cannot be written, read or recovered; the message names the file and why."""
