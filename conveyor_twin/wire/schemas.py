"""ros2msg definition texts of the contract types and their dependencies, as rosbag2 stores them.

A schema in a rosbag2 MCAP file (schema encoding ``ros2msg``) is the text of the root ``.msg``
file followed, for every type it depends on (depth first, each type once), by a separator line of
80 ``=``, a line ``MSG: pkg/Type`` and that type's ``.msg`` text. :func:`full_text` builds that
concatenation; :data:`SCHEMAS` holds it for every type the twin records.

The texts are the message definition files (:mod:`.msg_files`): the ``conveyor_twin_msgs``
texts are ``msg_defs/msg/*.msg`` byte for byte, the texts of the standard types those of the
Kilted message packages.
"""

import re
from typing import Dict, List, Tuple

from conveyor_twin.wire.msg_files import CONTRACT_PACKAGE, read_texts

#: Separator between the definitions of a concatenated ros2msg schema (rosbag2, mcap).
SEPARATOR = '=' * 80

#: ``.msg`` text of every known type, by full type name (``pkg/msg/Type``).
MSG_TEXTS: Dict[str, str] = read_texts()

#: Type names of the interface package of the contract.
CONTRACT_TYPES: Tuple[str, ...] = tuple(
    name for name in MSG_TEXTS if name.startswith(f'{CONTRACT_PACKAGE}/msg/'))

PRIMITIVES = frozenset((
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16', 'int32',
    'uint32', 'int64', 'uint64', 'string', 'wstring'))

_ARRAY = re.compile(r'\[(<=)?(\d*)\]$')
_BOUNDED_STRING = re.compile(r'^(w?string)<=(\d+)$')


class Field:
    """One field of a ``.msg`` definition (constants are not fields)."""

    __slots__ = ('name', 'base', 'array', 'capacity', 'string_capacity')

    def __init__(self, name: str, base: str, array: str, capacity: int,
                 string_capacity: int) -> None:
        """Describe a field.

        :param name: field name.
        :param base: primitive name (``float64``, ``string``) or full type name
            (``pkg/msg/Type``) of a nested type.
        :param array: ``''`` (single value), ``'fixed'``, ``'bounded'`` or ``'unbounded'``.
        :param capacity: array size (fixed) or upper bound (bounded), else 0.
        :param string_capacity: upper bound of a bounded string, else 0.
        """
        self.name = name
        self.base = base
        self.array = array
        self.capacity = capacity
        self.string_capacity = string_capacity

    def __repr__(self) -> str:
        return f'Field({self.name!r}, {self.base!r}, {self.array!r}, {self.capacity})'


def parse_fields(type_name: str, text: str) -> List[Field]:
    """Return the fields of a ``.msg`` text, in order, without constants and comments.

    :param type_name: full name of the type the text defines (``pkg/msg/Type``), to resolve
        package-relative nested types.
    :param text: ``.msg`` text.
    :raises ValueError: on a line that is not a field or constant definition.
    """
    package = type_name.split('/')[0]
    fields = []
    for raw in text.splitlines():
        line = raw.split('#', 1)[0].strip()
        if not line:
            continue
        parts = line.split(None, 1)
        if len(parts) != 2:
            raise ValueError(f'{type_name}: cannot parse line {raw!r}')
        ftype, rest = parts
        rest = rest.strip()
        if '=' in rest.split()[0] or (len(rest.split()) > 1 and rest.split()[1].startswith('=')):
            continue  # constant
        name = rest.split()[0]
        array, capacity = '', 0
        match = _ARRAY.search(ftype)
        if match:
            ftype = ftype[:match.start()]
            if match.group(1):
                array, capacity = 'bounded', int(match.group(2))
            elif match.group(2):
                array, capacity = 'fixed', int(match.group(2))
            else:
                array = 'unbounded'
        string_capacity = 0
        bounded = _BOUNDED_STRING.match(ftype)
        if bounded:
            ftype, string_capacity = bounded.group(1), int(bounded.group(2))
        if ftype in PRIMITIVES:
            base = ftype
        elif '/' in ftype:
            pkg, name_ = ftype.split('/')[0], ftype.split('/')[-1]
            base = f'{pkg}/msg/{name_}'
        else:
            base = f'{package}/msg/{ftype}'
        fields.append(Field(name, base, array, capacity, string_capacity))
    return fields


def dependencies(type_name: str) -> List[str]:
    """Return the nested types of a type in the order rosbag2 concatenates them.

    rosbag2 (``rosbag2_storage_mcap``) visits the dependencies of each type sorted by name,
    depth first, each type once.

    :param type_name: full type name (``pkg/msg/Type``) present in :data:`MSG_TEXTS`.
    """
    seen: List[str] = []

    def visit(name: str) -> None:
        nested = sorted({f.base for f in parse_fields(name, MSG_TEXTS[name])} - PRIMITIVES,
                        key=_short_name)
        for dep in nested:
            if dep not in seen:
                seen.append(dep)
                visit(dep)

    visit(type_name)
    return seen


def _short_name(type_name: str) -> str:
    """Return ``pkg/Type`` for ``pkg/msg/Type``."""
    pkg, _, name = type_name.split('/')
    return f'{pkg}/{name}'


def full_text(type_name: str) -> str:
    """Return the concatenated ros2msg schema text of a type, as rosbag2 writes it.

    :param type_name: full type name (``pkg/msg/Type``) present in :data:`MSG_TEXTS`.
    :raises KeyError: for an unknown type.
    """
    text = MSG_TEXTS[type_name]
    for dep in dependencies(type_name):
        text += f'\n{SEPARATOR}\nMSG: {_short_name(dep)}\n{MSG_TEXTS[dep]}'
    return text


#: Concatenated schema text of every known type, by full type name.
SCHEMAS: Dict[str, str] = {name: full_text(name) for name in MSG_TEXTS}
