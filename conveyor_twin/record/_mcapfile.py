"""Lean MCAP writer: chunked, indexed, with summary; messages are appended without copies.

``mcap.writer.Writer`` copies every message through ``BytesIO`` buffers (about 70 us for a
54 kB PartStates here); this writer keeps the records of the open chunk as a list of ``bytes``
and joins them once when the chunk is closed. Schema, channel, metadata and attachment records
are written to the data section outside chunks, immediately, so a linear read of a file cut
short still finds every channel of the intact chunks. Summary records are built with
``mcap.records`` (same code the reference reader parses).
"""

import functools
import struct
from typing import BinaryIO, Dict, List, Tuple
import zlib

from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (Attachment, AttachmentIndex, Channel, ChunkIndex, DataEnd, Footer,
                          Header, Metadata, MetadataIndex, Schema, Statistics, SummaryOffset)

MAGIC = b'\x89MCAP0\r\n'
COMPRESSIONS = ('lz4', 'zstd', '')

_MESSAGE = struct.Struct('<BQHIQQ')  # opcode, record length, channel, sequence, log, publish
_CHUNK_HEAD = struct.Struct('<BQQQQI')  # opcode, length, start, end, uncompressed size, crc
_U32 = struct.Struct('<I')
_U64 = struct.Struct('<Q')


def _compressor(compression: str):
    if compression == 'lz4':
        import lz4.frame
        # independent blocks: ~40 % faster here, a standard LZ4 frame all readers accept
        return functools.partial(lz4.frame.compress, block_linked=False)
    if compression == 'zstd':
        import zstandard
        return zstandard.ZstdCompressor(level=1).compress
    if compression == '':
        return None
    raise ValueError(f'unknown chunk compression {compression!r}, expected one of '
                     f'{COMPRESSIONS}')


class McapFile:
    """Write one MCAP file to a binary stream (not thread-safe: one writer thread)."""

    def __init__(self, stream: BinaryIO, *, profile: str, library: str, compression: str,
                 chunk_size: int) -> None:
        """Start the file (magic and header record).

        :param stream: binary output, positioned at its start.
        :param profile: MCAP profile (``ros2``).
        :param library: writer identification.
        :param compression: ``'lz4'``, ``'zstd'`` or ``''`` (none).
        :param chunk_size: uncompressed chunk size that closes a chunk [bytes].
        """
        self._stream = stream
        self._compress = _compressor(compression)
        self.compression = compression
        self.chunk_size = chunk_size
        self._pos = 0
        self._schemas: Dict[int, Schema] = {}
        self._channels: Dict[int, Channel] = {}
        # (start, end, offset, length, packed index offsets, index length, stored, size)
        self._chunk_indexes: List[Tuple[int, int, int, int, bytes, int, int, int]] = []
        self._attachment_indexes: List[AttachmentIndex] = []
        self._metadata_indexes: List[MetadataIndex] = []
        self._channel_counts: Dict[int, int] = {}
        self.message_count = 0
        self._start_time = 0
        self._end_time = 0
        self._reset_chunk()
        self._write(MAGIC)
        self._write_record(Header(profile=profile, library=library))

    # -- low level ---------------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        self._stream.write(data)
        self._pos += len(data)

    def _write_record(self, record) -> int:
        builder = RecordBuilder()
        record.write(builder)
        data = builder.end()
        offset = self._pos
        self._write(data)
        return offset

    def _reset_chunk(self) -> None:
        self._parts: List[bytes] = []
        self._chunk_bytes = 0
        self._chunk_index: Dict[int, List[int]] = {}
        self._chunk_start = 0
        self._chunk_end = 0

    # -- records ------------------------------------------------------------------------------
    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Write a schema record and return its id."""
        schema = Schema(id=len(self._schemas) + 1, name=name, encoding=encoding, data=data)
        self._schemas[schema.id] = schema
        self._write_record(schema)
        return schema.id

    def add_channel(self, topic: str, message_encoding: str, schema_id: int,
                    metadata: Dict[str, str]) -> int:
        """Write a channel record and return its id."""
        channel = Channel(id=len(self._channels) + 1, topic=topic,
                          message_encoding=message_encoding, schema_id=schema_id,
                          metadata=dict(metadata))
        self._channels[channel.id] = channel
        self._channel_counts[channel.id] = 0
        self._write_record(channel)
        return channel.id

    def add_message(self, channel_id: int, sequence: int, log_time: int, publish_time: int,
                    data: bytes) -> None:
        """Append a message to the open chunk; close the chunk when it is full.

        :param log_time: time the message was recorded [ns] (here: simulation time).
        :param publish_time: time the message was published [ns].
        """
        if self._chunk_bytes == 0:
            self._chunk_start = self._chunk_end = log_time
        elif log_time < self._chunk_start:
            self._chunk_start = log_time
        elif log_time > self._chunk_end:
            self._chunk_end = log_time
        index = self._chunk_index.get(channel_id)
        if index is None:
            index = self._chunk_index[channel_id] = []
        index.append(log_time)
        index.append(self._chunk_bytes)
        head = _MESSAGE.pack(Opcode.MESSAGE, 22 + len(data), channel_id, sequence, log_time,
                             publish_time)
        self._parts.append(head)
        self._parts.append(data)
        self._chunk_bytes += 31 + len(data)
        if self.message_count == 0:
            self._start_time = self._end_time = log_time
        else:
            self._start_time = min(self._start_time, log_time)
            self._end_time = max(self._end_time, log_time)
        self.message_count += 1
        self._channel_counts[channel_id] += 1
        if self._chunk_bytes >= self.chunk_size:
            self.close_chunk()

    def close_chunk(self) -> None:
        """Write the open chunk and its message indexes (nothing if it is empty)."""
        if not self._chunk_bytes:
            return
        size = self._chunk_bytes
        if self._compress:
            records = b''.join(self._parts)
            crc = zlib.crc32(records)
            data = self._compress(records)
            stored = len(data)
        else:  # no join: the parts go to the stream as they are
            crc = 0
            for part in self._parts:
                crc = zlib.crc32(part, crc)
            stored = size
        name = self.compression.encode()
        length = 8 + 8 + 8 + 4 + 4 + len(name) + 8 + stored
        chunk_offset = self._pos
        self._write(_CHUNK_HEAD.pack(Opcode.CHUNK, length, self._chunk_start, self._chunk_end,
                                     size, crc) + _U32.pack(len(name)) + name
                    + _U64.pack(stored))
        if self._compress:
            self._write(data)
        else:
            self._stream.writelines(self._parts)
            self._pos += size
        chunk_length = self._pos - chunk_offset
        index_offsets = {}
        index_start = self._pos
        for channel_id, entries in self._chunk_index.items():
            index_offsets[channel_id] = self._pos
            body = struct.pack(f'<HI{len(entries)}Q', channel_id, 8 * len(entries), *entries)
            self._write(struct.pack('<BQ', Opcode.MESSAGE_INDEX, len(body)) + body)
        # kept compact until finish(): a long recording has ~10^5 chunks, and an mcap
        # ChunkIndex object with its dict takes ~1.6 kB where this tuple takes ~0.2 kB
        packed = struct.pack(f'<{2 * len(index_offsets)}Q',
                             *(v for item in index_offsets.items() for v in item))
        self._chunk_indexes.append((self._chunk_start, self._chunk_end, chunk_offset,
                                    chunk_length, packed, self._pos - index_start, stored, size))
        self._reset_chunk()

    def _chunk_index_record(self, entry: Tuple[int, int, int, int, bytes, int, int, int]
                            ) -> ChunkIndex:
        """Return the ChunkIndex record of a compact entry of ``_chunk_indexes``."""
        start, end, offset, length, packed, index_length, stored, size = entry
        values = struct.unpack(f'<{len(packed) // 8}Q', packed)
        return ChunkIndex(
            message_start_time=start, message_end_time=end, chunk_start_offset=offset,
            chunk_length=length, message_index_offsets=dict(zip(values[::2], values[1::2])),
            message_index_length=index_length, compression=self.compression,
            compressed_size=stored, uncompressed_size=size)

    def add_metadata(self, name: str, metadata: Dict[str, str]) -> None:
        """Write a metadata record (outside chunks)."""
        offset = self._write_record(Metadata(name=name, metadata=dict(metadata)))
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=self._pos - offset,
                                                    name=name))

    def add_attachment(self, name: str, media_type: str, data: bytes, log_time: int = 0,
                       create_time: int = 0) -> None:
        """Write an attachment record (outside chunks)."""
        offset = self._write_record(Attachment(create_time=create_time, log_time=log_time,
                                               name=name, media_type=media_type, data=data))
        self._attachment_indexes.append(AttachmentIndex(
            offset=offset, length=self._pos - offset, create_time=create_time,
            log_time=log_time, data_size=len(data), name=name, media_type=media_type))

    def flush(self) -> None:
        """Close the open chunk and flush the stream (no fsync)."""
        self.close_chunk()
        self._stream.flush()

    def channel_counts(self) -> Dict[int, int]:
        """Return the number of messages written per channel id."""
        return dict(self._channel_counts)

    def time_range(self) -> Tuple[int, int]:
        """Return (first, last) log time written [ns]; (0, 0) without messages."""
        return self._start_time, self._end_time

    def finish(self) -> None:
        """Close the chunk, write data end, summary, footer and the closing magic; flush."""
        self.close_chunk()
        self._write_record(DataEnd(data_section_crc=0))
        summary_start = self._pos
        summary = RecordBuilder()
        offsets = []

        def group(opcode: int, records) -> None:
            start = summary.count
            for record in records:
                record.write(summary)
            if summary.count > start:
                offsets.append(SummaryOffset(group_opcode=opcode,
                                             group_start=summary_start + start,
                                             group_length=summary.count - start))

        group(Opcode.SCHEMA, self._schemas.values())
        group(Opcode.CHANNEL, self._channels.values())
        group(Opcode.STATISTICS, [Statistics(
            message_count=self.message_count, schema_count=len(self._schemas),
            channel_count=len(self._channels), attachment_count=len(self._attachment_indexes),
            metadata_count=len(self._metadata_indexes), chunk_count=len(self._chunk_indexes),
            message_start_time=self._start_time, message_end_time=self._end_time,
            channel_message_counts=dict(self._channel_counts))])
        group(Opcode.CHUNK_INDEX, (self._chunk_index_record(e) for e in self._chunk_indexes))
        group(Opcode.ATTACHMENT_INDEX, self._attachment_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        data = summary.end()
        crc = zlib.crc32(data)
        crc = zlib.crc32(struct.pack('<BQQQ', Opcode.FOOTER, 20, summary_start,
                                     summary_offset_start), crc)
        self._write(data)
        self._write_record(Footer(summary_start=summary_start,
                                  summary_offset_start=summary_offset_start, summary_crc=crc))
        self._write(MAGIC)
        self._stream.flush()
