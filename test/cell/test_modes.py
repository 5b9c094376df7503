"""Modes of the cell model are Enums whose members behave as their strings."""

import json

from conveyor_twin.cell import load_cell
from conveyor_twin.cell.model import (CONTACT_MODELS, ContactModel, MACRO_SCHEMES, MACRO_VARIANTS,
                                      MacroScheme, MacroVariant, OBSTACLE_KINDS, ObstacleKind,
                                      ZONE_POLICIES, ZonePolicy)


def test_the_loader_gives_enum_members() -> None:
    cell = load_cell(None)
    assert type(cell.micro.contact) is ContactModel
    assert type(cell.macro.variant) is MacroVariant
    assert type(cell.macro.scheme) is MacroScheme
    assert all(type(z.policy) is ZonePolicy for z in cell.zones)
    assert all(type(o.kind) is ObstacleKind for o in cell.obstacles)


def test_members_compare_hash_and_format_as_their_strings() -> None:
    for enum, names in ((ZonePolicy, ZONE_POLICIES), (ContactModel, CONTACT_MODELS),
                        (MacroVariant, MACRO_VARIANTS), (MacroScheme, MACRO_SCHEMES),
                        (ObstacleKind, OBSTACLE_KINDS)):
        assert tuple(m.value for m in enum) == names
        for member, name in zip(enum, names):
            assert member == name and hash(member) == hash(name)
            assert enum(name) is member
            assert str(member) == name and f'{member}' == name and '%s' % member == name
            assert json.dumps(member) == json.dumps(name)
    assert ZonePolicy.AUTO in ('macro', 'auto') and ContactModel.PENALTY != 'impulse'
