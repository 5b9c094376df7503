"""Linear, bounds-checked scan of an MCAP file that may be truncated or damaged.

The scan walks the records of the data section one by one (every step advances by at least
the 9-byte record prefix, so it always ends). A chunk whose compression, size or CRC does not
check out, or whose inner records do not parse, is reported as damaged and skipped as a whole;
a record prefix that runs past the end of the file, or an unknown opcode (a corrupted length
sends the scan into garbage), ends the scan with the reason. Messages come out in file order
(``log_time_order=False``).
"""

import mmap
import struct
from typing import Callable, Dict, Iterator, List, NamedTuple, Optional, Tuple
import zlib

from .errors import RecordingError

MAGIC = b'\x89MCAP0\r\n'
_PREFIX = struct.Struct('<BQ')
_U16 = struct.Struct('<H')
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')
_MESSAGE = struct.Struct('<HIQQ')
_CHUNK = struct.Struct('<QQQI')
_KNOWN = frozenset(range(0x01, 0x10))
_NAMES = {0x01: 'header', 0x03: 'schema', 0x04: 'channel', 0x05: 'message', 0x06: 'chunk',
          0x09: 'attachment', 0x0C: 'metadata'}


class Corrupt(Exception):
    """A record does not parse within its bounds."""


class ScanSchema(NamedTuple):
    """A schema record."""

    id: int
    name: str
    encoding: str
    data: bytes


class ScanChannel(NamedTuple):
    """A channel record."""

    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: Dict[str, str]


class ScanMessage(NamedTuple):
    """A message record."""

    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: bytes


class _Cursor:
    def __init__(self, buf, start: int, end: int) -> None:
        self.buf, self.pos, self.end = buf, start, end

    def take(self, size: int) -> int:
        start = self.pos
        if size < 0 or start + size > self.end:
            raise Corrupt(f'field of {size} bytes runs past the record end')
        self.pos = start + size
        return start

    def u16(self) -> int:
        return _U16.unpack_from(self.buf, self.take(2))[0]

    def u32(self) -> int:
        return _U32.unpack_from(self.buf, self.take(4))[0]

    def u64(self) -> int:
        return _U64.unpack_from(self.buf, self.take(8))[0]

    def raw(self, size: int) -> bytes:
        start = self.take(size)
        return bytes(self.buf[start:start + size])

    def string(self) -> str:
        try:
            return self.raw(self.u32()).decode('utf-8')
        except UnicodeDecodeError as err:
            raise Corrupt(f'string is not UTF-8: {err}') from None

    def string_map(self) -> Dict[str, str]:
        inner = _Cursor(self.buf, 0, 0)
        length = self.u32()
        inner.pos = self.take(length)
        inner.end = inner.pos + length
        result = {}
        while inner.pos < inner.end:
            key = inner.string()
            result[key] = inner.string()
        return result


def _schema(c: _Cursor) -> ScanSchema:
    return ScanSchema(c.u16(), c.string(), c.string(), c.raw(c.u32()))


def _channel(c: _Cursor) -> ScanChannel:
    return ScanChannel(c.u16(), c.u16(), c.string(), c.string(), c.string_map())


def _message(c: _Cursor) -> ScanMessage:
    head = _MESSAGE.unpack_from(c.buf, c.take(_MESSAGE.size))
    return ScanMessage(*head, c.raw(c.end - c.pos))


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    try:
        if compression == '':
            return data
        if compression == 'lz4':
            import lz4.frame
            return lz4.frame.decompress(data)
        if compression == 'zstd':
            import zstandard
            return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    except Exception as err:  # noqa: BLE001 - any decompressor failure means a damaged chunk
        raise Corrupt(f'{compression} decompression failed: {err}') from None
    raise Corrupt(f'unknown chunk compression {compression!r}')


class ScanReport:
    """What a linear scan found: records, damage and where and why it stopped."""

    def __init__(self, path: str, size: int) -> None:
        self.path = path
        self.size = size
        self.profile = ''
        self.library = ''
        self.schemas: Dict[int, ScanSchema] = {}
        self.channels: Dict[int, ScanChannel] = {}
        self.metadata: List[Tuple[str, Dict[str, str]]] = []
        self.attachments: List[Tuple[str, str, bytes]] = []
        self.compressions: set = set()
        self.chunks = 0
        self.damaged: List[Tuple[int, str]] = []
        self.complete = False
        self.stop_offset = 0
        self.stop_reason = ''


def scan(path: str, on_message: Optional[Callable[[ScanMessage], None]] = None) -> ScanReport:
    """Scan a file linearly, calling ``on_message`` for every intact message in file order.

    :param path: MCAP file.
    :param on_message: called with each message of an intact chunk (or outside chunks).
    :raises RecordingError: if the file cannot be read or is not MCAP at all.
    """
    report = ScanReport(path, 0)
    for message in iter_scan(path, report):
        if on_message is not None:
            on_message(message)
    return report


def iter_scan(path: str, report: ScanReport) -> Iterator[ScanMessage]:
    """Yield the intact messages of a file in file order, filling ``report`` as it goes.

    :raises RecordingError: if the file cannot be read or is not MCAP at all.
    """
    try:
        with open(path, 'rb') as f:
            report.size = f.seek(0, 2)
            if report.size == 0:
                raise RecordingError(f'{path} is empty, not an MCAP recording')
            with mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
                yield from _scan(mm, report)
    except OSError as err:
        raise RecordingError(f'cannot read {path}: {err}') from None


def _scan(mm, report: ScanReport) -> Iterator[ScanMessage]:
    size = report.size
    if size < 8 or mm[:8] != MAGIC:
        raise RecordingError(f'{report.path} does not start with the MCAP magic: not an MCAP '
                             'file')
    pos = 8
    while True:
        report.stop_offset = pos
        if pos == size:
            report.stop_reason = 'end of file without footer (recording not closed)'
            return
        if pos + 9 > size:
            report.stop_reason = f'truncated record prefix at byte {pos}'
            return
        opcode, length = _PREFIX.unpack_from(mm, pos)
        if opcode not in _KNOWN:
            report.stop_reason = f'unknown opcode 0x{opcode:02x} at byte {pos} (corrupt data)'
            return
        end = pos + 9 + length
        if end > size:
            report.stop_reason = (f'record 0x{opcode:02x} at byte {pos} runs {end - size} '
                                  'bytes past the end of the file (truncated)')
            return
        cursor = _Cursor(mm, pos + 9, end)
        messages: List[ScanMessage] = []
        try:
            if opcode == 0x01:
                report.profile, report.library = cursor.string(), cursor.string()
            elif opcode == 0x02:
                report.complete = True
                report.stop_reason = 'footer'
                return
            elif opcode == 0x03:
                schema = _schema(cursor)
                report.schemas[schema.id] = schema
            elif opcode == 0x04:
                channel = _channel(cursor)
                report.channels[channel.id] = channel
            elif opcode == 0x05:
                messages = [_message(cursor)]
            elif opcode == 0x06:
                messages = _chunk(cursor, report)
            elif opcode == 0x09:
                cursor.u64()
                cursor.u64()
                name, media_type = cursor.string(), cursor.string()
                data = cursor.raw(cursor.u64())
                covered = bytes(mm[pos + 9:cursor.pos])  # the CRC covers all fields before it
                crc = cursor.u32()
                if crc and zlib.crc32(covered) != crc:
                    raise Corrupt(f'attachment {name!r} fails its CRC')
                report.attachments.append((name, media_type, data))
            elif opcode == 0x0C:
                report.metadata.append((cursor.string(), cursor.string_map()))
        except Corrupt as err:
            name = _NAMES.get(opcode, f'record 0x{opcode:02x}')
            report.damaged.append((pos, f'{name}: {err}'))
        pos = end
        yield from messages


def _chunk(c: _Cursor, report: ScanReport) -> List[ScanMessage]:
    _, _, usize, crc = _CHUNK.unpack_from(c.buf, c.take(_CHUNK.size))
    compression = c.string()
    report.compressions.add(compression or 'none')
    data = c.raw(c.u64())
    records = _decompress(compression, data, usize)
    if len(records) != usize:
        raise Corrupt(f'chunk decompresses to {len(records)} bytes, header says {usize}')
    if crc and zlib.crc32(records) != crc:
        raise Corrupt('chunk fails its CRC')
    inner = _Cursor(records, 0, len(records))
    schemas, channels, messages = [], [], []
    while inner.pos < inner.end:
        opcode, length = _PREFIX.unpack_from(records, inner.take(9))
        body = _Cursor(records, inner.take(length), inner.pos)
        if opcode == 0x03:
            schemas.append(_schema(body))
        elif opcode == 0x04:
            channels.append(_channel(body))
        elif opcode == 0x05:
            messages.append(_message(body))
        else:
            raise Corrupt(f'unexpected record 0x{opcode:02x} inside a chunk')
    report.chunks += 1
    for schema in schemas:
        report.schemas[schema.id] = schema
    for channel in channels:
        report.channels[channel.id] = channel
    return messages
