"""RIHS01 type description hashes (REP-2011), computed from the ros2msg texts of :mod:`schemas`.

rosbag2 (Jazzy and later) stores the hash of a topic's type in the channel metadata key
``topic_type_hash``. The hash is the SHA-256 of a canonical JSON rendering of the type
description: the type's fields and, sorted by name, every type it references, each field with
its type id, capacity, string capacity and nested type name (default values and constants are
not part of it). This follows ``rosidl_generator_type_description``; the tests check it against
the hashes that the message packages ship in ``share/<pkg>/msg/<Type>.json``.
"""

import hashlib
import json
from typing import Dict, List

from .schemas import Field, MSG_TEXTS, parse_fields, PRIMITIVES

RIHS01_PREFIX = 'RIHS01_'

# type_description_interfaces/msg/FieldType: ids of the value types. A .msg ``char`` is an IDL
# uint8 and a .msg ``byte`` an IDL octet.
_TYPE_IDS = {
    'nested': 1, 'int8': 2, 'uint8': 3, 'char': 3, 'int16': 4, 'uint16': 5, 'int32': 6,
    'uint32': 7, 'int64': 8, 'uint64': 9, 'float32': 10, 'float64': 11, 'bool': 15,
    'byte': 16, 'string': 17, 'wstring': 18, 'bounded_string': 21, 'bounded_wstring': 22,
}
# Offsets added to the value type id for fixed arrays, bounded and unbounded sequences.
_ARRAY_OFFSETS = {'': 0, 'fixed': 48, 'bounded': 96, 'unbounded': 144}


def _field_type(field: Field) -> Dict[str, object]:
    if field.base not in PRIMITIVES:
        value_id = _TYPE_IDS['nested']
    elif field.string_capacity:
        value_id = _TYPE_IDS['bounded_' + field.base]
    else:
        value_id = _TYPE_IDS[field.base]
    return {
        'type_id': value_id + _ARRAY_OFFSETS[field.array],
        'capacity': field.capacity,
        'string_capacity': field.string_capacity,
        'nested_type_name': '' if field.base in PRIMITIVES else field.base,
    }


def _individual(type_name: str) -> Dict[str, object]:
    fields = parse_fields(type_name, MSG_TEXTS[type_name])
    if not fields:  # rosidl adds a placeholder member to empty structures
        fields = [Field('structure_needs_at_least_one_member', 'uint8', '', 0, 0)]
    return {'type_name': type_name,
            'fields': [{'name': f.name, 'type': _field_type(f)} for f in fields]}


def referenced_types(type_name: str) -> List[str]:
    """Return every type a type references, directly or not, sorted by name.

    :param type_name: full type name (``pkg/msg/Type``) present in :data:`schemas.MSG_TEXTS`.
    """
    found: set = set()
    queue = [type_name]
    while queue:
        name = queue.pop()
        for field in parse_fields(name, MSG_TEXTS[name]):
            if field.base not in PRIMITIVES and field.base not in found:
                found.add(field.base)
                queue.append(field.base)
    return sorted(found)


def type_description(type_name: str) -> Dict[str, object]:
    """Return the hashable type description (no default values) of a type.

    :param type_name: full type name (``pkg/msg/Type``) present in :data:`schemas.MSG_TEXTS`.
    """
    return {
        'type_description': _individual(type_name),
        'referenced_type_descriptions': [_individual(n) for n in referenced_types(type_name)],
    }


def type_hash(type_name: str) -> str:
    """Return the RIHS01 hash string of a type, e.g. ``RIHS01_f49f...``.

    :param type_name: full type name (``pkg/msg/Type``) present in :data:`schemas.MSG_TEXTS`.
    :raises KeyError: for an unknown type.
    """
    text = json.dumps(type_description(type_name), skipkeys=False, ensure_ascii=True,
                      check_circular=True, allow_nan=False, indent=None,
                      separators=(', ', ': '), sort_keys=False)
    return RIHS01_PREFIX + hashlib.sha256(text.encode('utf-8')).hexdigest()
