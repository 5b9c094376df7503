"""The PLC tag map of a cell: every value the twin shows a PLC, by OPC UA path and Modbus address.

One :class:`Tag` per value, generated from the cell (:func:`tag_map`), the same map for the
OPC UA server (browse path below the twin object) and the Modbus server (table and address).

Order of :attr:`TagMap.tags` (and of ``conveyor-twin plc-map``): the twin's tags
(``SimulationTime``, ``Step``, ``Ledger/Entered``, ``Ledger/Left``, ``Ledger/InFlight``,
``FaultsActive``, ``RejectedWrites``, ``Mode``, ``ActiveFaults``), the lockstep tags
(``Lockstep/Done``, ``DoneTick``, ``Tick``, ``TickSteps``), then per light barrier, per belt
and per actuator in the cell's order. Modbus addresses are 0-based and contiguous per table in
this order, except that in the input registers the two 16-bit twin values (``Mode``,
``Lockstep/DoneTick``) come after the 32-bit ones, so every 32-bit value starts at an even
address and the twin's and lockstep's addresses are the same for every cell:

- discrete inputs: ``Lockstep/Done`` (0), then ``Barriers/<b>/Blocked`` (1, 2, ...);
- input registers: the twin's 32-bit values (0..13), ``Mode`` (14), ``Lockstep/DoneTick`` (15),
  then per barrier ``RisingEdges``, ``FallingEdges``, ``LastRisingTime``, ``LastFallingTime``
  (8 registers), per belt ``ActualSpeed`` (2), per actuator ``Position`` (2), then per actuator
  ``Load`` (2) (and the discrete inputs end with every actuator's ``Stalled``);
- holding registers: ``Lockstep/Tick`` (0), ``Lockstep/TickSteps`` (1), then per belt
  ``SpeedSetpoint`` (2), per actuator ``Target`` (2);
- coils: none.

Encoding: a 32-bit Modbus value takes two registers, high word first (big-endian word order,
"ABCD"); ``float32`` is IEEE-754. Times are milliseconds of simulation time as ``uint32`` in
Modbus (wrapping after 2^32 ms, 49.7 days), seconds as Double in OPC UA; counters and ``Step``
wrap modulo 2^32 in Modbus. ``Mode`` is a String in OPC UA, a ``uint16`` code in Modbus
(:data:`MODE_CODES`). ``ActiveFaults`` is OPC UA only; ``Lockstep/Tick``, ``TickSteps`` and
``DoneTick`` are Modbus only (OPC UA has the ``Step`` method instead).

A browse name is the cell's name with every character other than ``A-Z a-z 0-9 _ -`` replaced
by ``_`` (``/`` separates path elements); two names that become equal get ``_2``, ``_3``, ...
in cell order. :attr:`Tag.target` keeps the cell's name.
"""

from dataclasses import dataclass
from enum import Enum
import csv
import io
import math
import re
import struct
from typing import Dict, Iterable, List, Sequence, Tuple, Union

import numpy as np

from conveyor_twin.cell.model import Cell

#: The Modbus tables, in the order of :meth:`TagMap.to_csv`.
MODBUS_TABLES = ('coil', 'discrete', 'input', 'holding')

#: Modbus code of each time mode (``Mode``).
MODE_CODES: Dict[str, int] = {'realtime': 0, 'fast': 1, 'lockstep': 2}

#: Default of ``Lockstep/TickSteps``: steps per tick (10 steps = 10 ms at a 1 ms step).
DEFAULT_TICK_STEPS = 10

_UINT32 = 2 ** 32
_INVALID = re.compile(r'[^A-Za-z0-9_\-]')

Value = Union[bool, int, float, str]


class TagKind(str, Enum):
    """What a tag's value is (its OPC UA type: :attr:`opcua_type`)."""

    BOOL = 'bool'
    UINT32 = 'uint32'
    UINT64 = 'uint64'
    FLOAT64 = 'float64'
    STRING = 'string'

    @property
    def opcua_type(self) -> str:
        """The OPC UA built-in type name (``Boolean``, ``UInt32``, ``UInt64``, ``Double``,
        ``String``)."""
        return _OPCUA_TYPES[self]


_OPCUA_TYPES = {TagKind.BOOL: 'Boolean', TagKind.UINT32: 'UInt32', TagKind.UINT64: 'UInt64',
                TagKind.FLOAT64: 'Double', TagKind.STRING: 'String'}
_WORDS = {'bit': 1, 'uint16': 1, 'uint32': 2, 'float32': 2}


@dataclass(frozen=True)
class Tag:
    """One value the twin shows a PLC.

    :param path: OPC UA browse path below the twin object, '/'-joined
        (``'Barriers/lb_entry/Blocked'``).
    :param kind: what the value is (OPC UA type).
    :param unit: ``''``, ``'s'``, ``'m/s'``, ``'m'``, ``'rad'`` or ``'1'`` (parts).
    :param writable: a PLC may write it.
    :param description: one line for the map.
    :param modbus_table: ``'coil'``, ``'discrete'``, ``'input'``, ``'holding'``, or ``''`` for
        an OPC UA only tag.
    :param modbus_address: first 0-based address in its table (-1 without Modbus).
    :param modbus_words: 16-bit registers it takes (1 for a bit; 0 without Modbus).
    :param modbus_type: ``'bit'``, ``'uint16'``, ``'uint32'``, ``'float32'`` or ``''``.
    :param source: what it shows: ``('twin', 'time')``, ``('barrier', index, 'blocked')``,
        ``('belt', index, 'setpoint')``, ``('actuator', index, 'target')``,
        ``('ledger', 'entered')``, ``('lockstep', 'tick')``, ...
    :param target: the cell's name of its barrier, belt or actuator ('' for the twin's tags).
    :param opcua: the OPC UA server shows it.
    """

    path: str
    kind: TagKind
    unit: str
    writable: bool
    description: str
    modbus_table: str
    modbus_address: int
    modbus_words: int
    modbus_type: str
    source: tuple
    target: str = ''
    opcua: bool = True


class TagMap:
    """The tags of one cell, in the documented order (module docstring).

    :param tags: the tags; paths unique, Modbus addresses contiguous per table.
    """

    def __init__(self, tags: Sequence[Tag]) -> None:
        self.tags: Tuple[Tag, ...] = tuple(tags)
        self._by_path = {t.path: t for t in self.tags}
        if len(self._by_path) != len(self.tags):
            raise ValueError('TagMap: duplicate tag paths')
        self._tables = {table: tuple(sorted((t for t in self.tags if t.modbus_table == table),
                                            key=lambda t: t.modbus_address))
                        for table in MODBUS_TABLES}

    def by_path(self, path: str) -> Tag:
        """Return the tag at ``path``; raise KeyError naming it if there is none."""
        try:
            return self._by_path[path]
        except KeyError:
            raise KeyError(f'no PLC tag {path!r}') from None

    def modbus(self, table: str) -> Tuple[Tag, ...]:
        """Return the tags of one Modbus table by address (``coil``, ``discrete``, ``input``,
        ``holding``)."""
        if table not in self._tables:
            raise ValueError(f'unknown Modbus table {table!r} (expected one of '
                             f'{", ".join(MODBUS_TABLES)})')
        return self._tables[table]

    def modbus_size(self, table: str) -> int:
        """Return the number of addresses (bits or registers) ``table`` uses."""
        tags = self.modbus(table)
        return tags[-1].modbus_address + tags[-1].modbus_words if tags else 0

    def rows(self) -> List[Tuple[str, ...]]:
        """Return the map as text rows: path, OPC UA type, unit, access, Modbus table,
        address, words, type, description (the header first)."""
        rows = [('path', 'opcua_type', 'unit', 'access', 'modbus_table', 'modbus_address',
                 'modbus_words', 'modbus_type', 'description')]
        for t in self.tags:
            address = str(t.modbus_address) if t.modbus_table else ''
            words = str(t.modbus_words) if t.modbus_table else ''
            rows.append((t.path if t.opcua else f'({t.path})', t.kind.opcua_type, t.unit,
                         'read/write' if t.writable else 'read', t.modbus_table, address,
                         words, t.modbus_type, t.description))
        return rows

    def to_csv(self) -> str:
        """Return the map as CSV (one row per tag, a header row first)."""
        out = io.StringIO()
        writer = csv.writer(out, lineterminator='\n')
        writer.writerows(self.rows())
        return out.getvalue()

    def to_markdown(self) -> str:
        """Return the map as a Markdown table (one row per tag)."""
        rows = self.rows()
        lines = ['| ' + ' | '.join(rows[0]) + ' |', '|' + '---|' * len(rows[0])]
        lines += ['| ' + ' | '.join(_md(cell) for cell in row) + ' |' for row in rows[1:]]
        return '\n'.join(lines) + '\n'


def _md(text: str) -> str:
    if text.startswith('(') and text.endswith(')'):  # not shown by OPC UA
        text = text[1:-1] + ' (Modbus only)'
    return text.replace('|', '\\|')


def browse_names(names: Iterable[str]) -> List[str]:
    """Return a valid, unique browse name for each of ``names`` (module docstring)."""
    out: List[str] = []
    seen = set()
    for name in names:
        base = _INVALID.sub('_', name) or '_'
        candidate, k = base, 2
        while candidate in seen:
            candidate = f'{base}_{k}'
            k += 1
        seen.add(candidate)
        out.append(candidate)
    return out


class _Builder:
    """Assigns addresses per table in the order tags are added."""

    def __init__(self) -> None:
        self.tags: List[Tag] = []
        self.next = {table: 0 for table in MODBUS_TABLES}

    def add(self, path: str, kind: TagKind, unit: str, description: str, source: tuple, *,
            table: str = '', mtype: str = '', writable: bool = False, target: str = '',
            opcua: bool = True) -> None:
        address, words = -1, 0
        if table:
            words = _WORDS[mtype]
            address = self.next[table]
            self.next[table] += words
        self.tags.append(Tag(path, kind, unit, writable, description, table, address, words,
                             mtype, source, target, opcua))


def tag_map(cell: Cell) -> TagMap:
    """Return the PLC tag map of ``cell`` (same cell, same map)."""
    b = _Builder()
    k = TagKind
    # the twin: 32-bit input registers first, then the 16-bit ones
    b.add('SimulationTime', k.FLOAT64, 's', 'simulation time (Modbus: ms, uint32)',
          ('twin', 'time'), table='input', mtype='uint32')
    b.add('Step', k.UINT64, '', 'step index (Modbus: modulo 2^32)', ('twin', 'step'),
          table='input', mtype='uint32')
    b.add('Ledger/Entered', k.FLOAT64, '1', 'parts that entered the cell',
          ('ledger', 'entered'), table='input', mtype='float32')
    b.add('Ledger/Left', k.FLOAT64, '1', 'parts that left the cell through sinks',
          ('ledger', 'left'), table='input', mtype='float32')
    b.add('Ledger/InFlight', k.FLOAT64, '1', 'parts in the cell (macro: fractional)',
          ('ledger', 'in_flight'), table='input', mtype='float32')
    b.add('FaultsActive', k.UINT32, '', 'number of active faults', ('twin', 'faults_active'),
          table='input', mtype='uint32')
    b.add('RejectedWrites', k.UINT32, '', 'commands rejected so far',
          ('twin', 'rejected_writes'), table='input', mtype='uint32')
    b.add('Mode', k.STRING, '', 'time mode (Modbus: 0 realtime, 1 fast, 2 lockstep)',
          ('twin', 'mode'), table='input', mtype='uint16')
    b.add('ActiveFaults', k.STRING, '', 'active faults, "id kind target" separated by "; "',
          ('twin', 'active_faults'))
    # lockstep
    b.add('Lockstep/Done', k.BOOL, '', 'no step request is running', ('lockstep', 'done'),
          table='discrete', mtype='bit')
    b.add('Lockstep/DoneTick', k.UINT32, '', 'equals Lockstep/Tick when its steps are done',
          ('lockstep', 'done_tick'), table='input', mtype='uint16', opcua=False)
    b.add('Lockstep/Tick', k.UINT32, '', 'increment (mod 65536) to step TickSteps steps',
          ('lockstep', 'tick'), table='holding', mtype='uint16', writable=True, opcua=False)
    b.add('Lockstep/TickSteps', k.UINT32, '', 'steps per tick (default 10)',
          ('lockstep', 'tick_steps'), table='holding', mtype='uint16', writable=True,
          opcua=False)
    for i, (barrier, name) in enumerate(zip(cell.light_barriers,
                                            browse_names(lb.name for lb in cell.light_barriers))):
        p, t = f'Barriers/{name}/', barrier.name
        b.add(p + 'Blocked', k.BOOL, '', f'light barrier {t!r} is blocked',
              ('barrier', i, 'blocked'), table='discrete', mtype='bit', target=t)
        b.add(p + 'RisingEdges', k.UINT32, '', f'rising edges of {t!r} since start',
              ('barrier', i, 'rising'), table='input', mtype='uint32', target=t)
        b.add(p + 'FallingEdges', k.UINT32, '', f'falling edges of {t!r} since start',
              ('barrier', i, 'falling'), table='input', mtype='uint32', target=t)
        b.add(p + 'LastRisingTime', k.FLOAT64, 's',
              f'time of the last rising edge of {t!r} (Modbus: ms, uint32)',
              ('barrier', i, 'last_rising'), table='input', mtype='uint32', target=t)
        b.add(p + 'LastFallingTime', k.FLOAT64, 's',
              f'time of the last falling edge of {t!r} (Modbus: ms, uint32)',
              ('barrier', i, 'last_falling'), table='input', mtype='uint32', target=t)
    for i, (belt, name) in enumerate(zip(cell.belts, browse_names(x.name for x in cell.belts))):
        p, t = f'Belts/{name}/', belt.name
        b.add(p + 'SpeedSetpoint', k.FLOAT64, 'm/s',
              f'target speed of belt {t!r}, |v| <= {belt.max_speed:g}',
              ('belt', i, 'setpoint'), table='holding', mtype='float32', writable=True, target=t)
        b.add(p + 'ActualSpeed', k.FLOAT64, 'm/s', f'actual speed of belt {t!r}',
              ('belt', i, 'actual'), table='input', mtype='float32', target=t)
    for i, (actuator, name) in enumerate(zip(cell.actuators,
                                             browse_names(a.name for a in cell.actuators))):
        p, t = f'Actuators/{name}/', actuator.name
        unit = 'rad' if actuator.is_rotary else 'm'
        low, high = actuator.position_range
        b.add(p + 'Target', k.FLOAT64, unit,
              f'target position of {actuator.kind} {t!r}, in [{low:g}, {high:g}] {unit}',
              ('actuator', i, 'target'), table='holding', mtype='float32', writable=True,
              target=t)
        b.add(p + 'Position', k.FLOAT64, unit, f'position of {actuator.kind} {t!r}',
              ('actuator', i, 'position'), table='input', mtype='float32', target=t)
    # after the positions, so the addresses above stay those of cells before stalls existed
    for i, (actuator, name) in enumerate(zip(cell.actuators,
                                             browse_names(a.name for a in cell.actuators))):
        p, t = f'Actuators/{name}/', actuator.name
        b.add(p + 'Stalled', k.BOOL, '', f'{actuator.kind} {t!r} is stalled (load over its '
              'force_limit)', ('actuator', i, 'stalled'), table='discrete', mtype='bit',
              target=t)
        b.add(p + 'Load', k.FLOAT64, 'N', f'force of the parts on {actuator.kind} {t!r}',
              ('actuator', i, 'load'), table='input', mtype='float32', target=t)
    return TagMap(b.tags)


# --- Modbus encoding ---------------------------------------------------------------------

def modbus_words(tag: Tag, value: Value) -> Tuple[int, ...]:
    """Return the 16-bit registers (or the one bit, 0/1) of ``value`` of ``tag`` in Modbus.

    ``value`` is the tag's OPC UA value (seconds for times, the mode's name for ``Mode``);
    times become ms (rounded half up), 32-bit integers wrap modulo 2^32, a float beyond float32
    becomes infinite.
    """
    mtype = tag.modbus_type
    if mtype == 'bit':
        return (1 if value else 0,)
    if mtype == 'float32':
        try:
            packed = struct.pack('>f', float(value))
        except OverflowError:  # beyond float32: infinite
            packed = struct.pack('>f', math.copysign(math.inf, float(value)))
        high, low = struct.unpack('>HH', packed)
        return (high, low)
    if isinstance(value, str):
        number = MODE_CODES[value]
    elif tag.unit == 's':
        number = math.floor(value * 1e3 + 0.5) if math.isfinite(value) else 0
    else:
        number = int(value)
    if mtype == 'uint16':
        return (number & 0xFFFF,)
    if mtype == 'uint32':
        number %= _UINT32
        return (number >> 16, number & 0xFFFF)
    raise ValueError(f'tag {tag.path!r} has no Modbus encoding')


def float32_value(value: float) -> float:
    """Return the shortest decimal number that is the float32 ``value`` (0.008 for the float32
    nearest 0.008, which is 0.00800000038): a PLC writing a range limit as float32 means the
    limit, not a value just beyond it."""
    single = np.float32(value)
    return float(str(single)) if np.isfinite(single) else float(single)


def modbus_value(tag: Tag, words: Sequence[int]) -> Union[int, float]:
    """Return the value that the registers ``words`` (``tag.modbus_words`` of them, as a PLC
    wrote them) mean for ``tag``: a float for ``float32`` (:func:`float32_value`), an int
    otherwise (times in ms)."""
    if len(words) != tag.modbus_words:
        raise ValueError(f'tag {tag.path!r} takes {tag.modbus_words} registers, got {len(words)}')
    mtype = tag.modbus_type
    if mtype == 'float32':
        return float32_value(struct.unpack('>f', struct.pack('>HH', words[0], words[1]))[0])
    if mtype == 'uint32':
        return (words[0] << 16) | words[1]
    if mtype in ('uint16', 'bit'):
        return int(words[0])
    raise ValueError(f'tag {tag.path!r} has no Modbus encoding')
