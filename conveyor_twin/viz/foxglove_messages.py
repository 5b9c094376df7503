"""What the Foxglove view sends and takes besides the twin's own bytes: density grids as
``foxglove.Grid`` and the commands clients publish (strictly parsed).

Grids are built with the installed ``foxglove-sdk``'s message classes: ``foxglove.messages``
(0.30 and later; ``foxglove.schemas`` is its deprecated alias) whose numeric type enum is
``PackedElementFieldNumericType`` (older releases named it ``NumericType``).

A command published as JSON must be an object with the name (a non-empty string) and the value
(a JSON number, finite: not a string, a boolean, ``null``, ``NaN`` or ``Infinity``); a CDR
command's value must be finite. Anything else is refused with the reason, before the command
book sees it.
"""

import json
import math
from typing import Any, Tuple

import numpy as np

from conveyor_twin.wire import cdr

#: Command kinds and their (name field, value field, unit) in a JSON command.
COMMAND_FIELDS = {'belt': ('belt', 'speed', 'm/s'), 'actuator': ('actuator', 'position',
                                                                 'm or rad')}


class CommandParseError(ValueError):
    """A client's command message that is not a valid command (the text says why)."""


def _messages_module() -> Any:
    """Return the SDK module holding the message classes (``foxglove.messages``)."""
    try:
        from foxglove import messages
        return messages
    except ImportError:  # releases before foxglove.messages existed
        from foxglove import schemas
        return schemas


def _numeric_type(module: Any) -> Any:
    """Return the SDK's enum of packed field types, whatever the release names it."""
    for name in ('PackedElementFieldNumericType', 'NumericType'):
        enum = getattr(module, name, None)
        if enum is not None:
            return enum
    raise ImportError('foxglove-sdk: neither PackedElementFieldNumericType nor NumericType '
                      f'in {module.__name__}')


def density_grid(grid: cdr.DensityGridData) -> Any:
    """Return a ``foxglove.Grid`` of a DensityGrid: one float32 field ``density`` [parts/m²],
    row-major from the grid's origin corner, in the grid's frame."""
    m = _messages_module()
    float32 = _numeric_type(m).Float32
    ny, nx = grid.density.shape
    return m.Grid(
        timestamp=m.Timestamp(sec=grid.stamp_ns // 1_000_000_000,
                              nsec=grid.stamp_ns % 1_000_000_000),
        frame_id=grid.frame_id,
        pose=m.Pose(position=m.Vector3(x=grid.origin_x, y=grid.origin_y, z=0.001),
                    orientation=m.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
        column_count=nx, cell_size=m.Vector2(x=grid.resolution, y=grid.resolution),
        row_stride=4 * nx, cell_stride=4,
        fields=[m.PackedElementField(name='density', offset=0, type=float32)],
        data=np.ascontiguousarray(grid.density, '<f4').tobytes())


def _refuse_constant(name: str) -> float:
    raise CommandParseError(f'{name} is not a finite number')


def decode_command(kind: str, encoding: str, data: bytes) -> Tuple[str, float]:
    """Return (name, value) of a command a client published.

    :param kind: ``belt`` (value: speed [m/s]) or ``actuator`` (value: position [m or rad]).
    :param encoding: ``json`` or ``cdr``.
    :raises CommandParseError: for anything but a well-formed command with a finite value.
    """
    name_field, value_field, unit = COMMAND_FIELDS[kind]
    if encoding == 'json':
        try:
            msg = json.loads(bytes(data).decode('utf-8'), parse_constant=_refuse_constant)
        except CommandParseError:
            raise
        except (UnicodeDecodeError, ValueError) as exc:
            raise CommandParseError(f'not JSON ({exc})') from None
        if not isinstance(msg, dict):
            raise CommandParseError(f'expected a JSON object {{"{name_field}": ..., '
                                    f'"{value_field}": ...}}, got {type(msg).__name__}')
        for field in (name_field, value_field):
            if field not in msg:
                raise CommandParseError(f'field {field!r} is missing (got fields '
                                        f'{sorted(msg)})')
        name, value = msg[name_field], msg[value_field]
        if not isinstance(name, str) or not name:
            raise CommandParseError(f'field {name_field!r}: expected a non-empty string, got '
                                    f'{name!r}')
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise CommandParseError(f'field {value_field!r}: expected a JSON number [{unit}], '
                                    f'got {value!r} ({_json_type(value)})')
        try:
            value = float(value)
        except OverflowError:
            raise CommandParseError(f'field {value_field!r}: {value!r} is not a finite '
                                    'number') from None
    elif encoding == 'cdr':
        try:
            if kind == 'belt':
                name, value = cdr.decode_belt_command(bytes(data))
            else:
                name, value = cdr.decode_actuator_command(bytes(data))
        except (ValueError, IndexError, UnicodeDecodeError) as exc:
            raise CommandParseError(f'not a valid CDR message ({exc!r})') from None
    else:
        raise CommandParseError(f'encoding {encoding!r} is not cdr or json')
    if not math.isfinite(value):
        raise CommandParseError(f'field {value_field!r}: {value!r} is not a finite number')
    return name, value


def _json_type(value: Any) -> str:
    if value is None:
        return 'null'
    if isinstance(value, bool):
        return 'a boolean'
    if isinstance(value, str):
        return 'a string'
    return f'a JSON {type(value).__name__}'
