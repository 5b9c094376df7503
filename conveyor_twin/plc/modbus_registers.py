"""The Modbus tables of a cell's tag map: which tag owns each address.

:class:`ModbusTables` lays the tags of :func:`conveyor_twin.plc.tags.tag_map` out in the four
Modbus tables (coils, discrete inputs, input registers, holding registers) so that a request
for a range of addresses finds its tags, and tells whether a write covers whole values. The
words of a value come from :func:`~conveyor_twin.plc.tags.modbus_words` and
:func:`~conveyor_twin.plc.tags.modbus_value` (the encoding is documented in
:mod:`conveyor_twin.plc.tags`: 32-bit values high word first, float32 IEEE-754, times in ms
of simulation time).

Tables only (no sockets, no threads): the server, :mod:`conveyor_twin.plc.modbus_server`,
answers requests with them.
"""

from typing import Dict, List, Optional, Sequence, Tuple

from conveyor_twin.plc.tags import MODBUS_TABLES, Tag, TagMap

#: The table each Modbus function code reads (a write of a holding register reads it back
#: under the write's code), and writes.
READ_CODES = {1: 'coil', 2: 'discrete', 3: 'holding', 4: 'input', 6: 'holding', 22: 'holding',
              23: 'holding'}
WRITE_CODES = {5: 'coil', 15: 'coil', 6: 'holding', 16: 'holding', 22: 'holding',
               23: 'holding'}
#: Words of each Modbus type.
WORDS = {'bit': 1, 'uint16': 1, 'uint32': 2, 'float32': 2}


class LayoutError(ValueError):
    """A tag map that cannot be laid out in Modbus tables (overlapping or unknown entries)."""


class Table:
    """One Modbus table: the tag owning each address.

    :param name: ``coil``, ``discrete``, ``input`` or ``holding``.
    :param tags: the tags of this table.
    :raises LayoutError: if two tags overlap or a tag's type or size is unknown.
    """

    def __init__(self, name: str, tags: Sequence[Tag]) -> None:
        self.name = name
        self.tags: Tuple[Tag, ...] = tuple(sorted(tags, key=lambda t: t.modbus_address))
        size = max((t.modbus_address + t.modbus_words for t in self.tags), default=0)
        #: per address: (tag, word index within the tag), or None in a gap
        self.owners: List[Optional[Tuple[Tag, int]]] = [None] * size
        for tag in self.tags:
            words = WORDS.get(tag.modbus_type)
            if words is None or words != tag.modbus_words:
                raise LayoutError(f'Modbus {name} table: tag {tag.path!r}: type '
                                  f'{tag.modbus_type!r} with {tag.modbus_words} word(s); '
                                  f'expected one of {WORDS}')
            for word in range(words):
                address = tag.modbus_address + word
                if self.owners[address] is not None:
                    other = self.owners[address][0].path
                    raise LayoutError(f'Modbus {name} table: tags {other!r} and {tag.path!r} '
                                      f'share address {address}')
                self.owners[address] = (tag, word)

    @property
    def size(self) -> int:
        """Addresses from 0 to the last one in use, plus one."""
        return len(self.owners)

    def covers(self, address: int, count: int) -> bool:
        """True if every address of ``[address, address + count)`` belongs to a tag."""
        if count < 1 or address < 0 or address + count > len(self.owners):
            return False
        return all(owner is not None for owner in self.owners[address:address + count])

    def whole_tags(self, address: int, count: int) -> Optional[Tuple[Tag, ...]]:
        """Return the tags ``[address, address + count)`` holds if it starts and ends on tag
        boundaries (every tag whole), else None. The range must be :meth:`covers`-ed."""
        first = self.owners[address]
        last = self.owners[address + count - 1]
        if first[1] != 0 or last[1] != last[0].modbus_words - 1:
            return None
        return tuple(owner[0] for owner in self.owners[address:address + count]
                     if owner[1] == 0)


class ModbusTables:
    """The four Modbus tables of a tag map (tags without a Modbus table are left out).

    :param tags: the cell's tag map.
    :raises LayoutError: on a tag map that cannot be laid out.
    """

    def __init__(self, tags: TagMap) -> None:
        self.tables: Dict[str, Table] = {
            name: Table(name, tags.modbus(name)) for name in MODBUS_TABLES}

    def __getitem__(self, name: str) -> Table:
        return self.tables[name]
