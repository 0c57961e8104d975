"""The recovering backend of ``LogReader``: a walk over the top-level MCAP records.

Used when a file has no usable summary (a robot that lost power mid-recording, a
damaged summary) or when the indexed backend meets an index that does not match the
file. Records come in file order, as far as the file is intact: a whole record that
fails to parse (a corrupt chunk) is skipped and counted, a chunk cut off by the end of
the file gives the messages of its intact compressed blocks (zstd and lz4 frames decode
block by block), and a record whose framing is broken (an unknown opcode, a length
past the data section) is skipped up to the next chunk the summary knows of, when there
is one (``sync``). Records follow the MCAP specification (https://mcap.dev/spec,
"Records").
"""

from __future__ import annotations

import bisect
import io
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Attachment, Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import get_chunk_data_stream

MCAP_MAGIC = b"\x89MCAP0\r\n"
RECORD_HEAD = struct.Struct("<BQ")  # opcode u8, record length u64
_VALID_OPCODES = frozenset(range(0x01, 0x10))


@dataclass
class Damage:
    """What reading a file found wrong with it (``LogReader.damage``)."""

    truncated: bool = False
    lost_bytes: int = 0
    damaged_records: int = 0
    salvaged_messages: int = 0
    undecodable: int = 0
    seen: set[int] = field(default_factory=set)

    def record(self, offset: int, nbytes: int) -> None:
        """Count the damaged record at file ``offset`` (``nbytes`` of it lost), once
        however many times (and by whichever backend) it is met."""
        if offset not in self.seen:
            self.seen.add(offset)
            self.damaged_records += 1
            self.lost_bytes += int(nbytes)


_CHUNK_RECORDS: dict[int, Any] = {
    Opcode.SCHEMA: Schema,
    Opcode.CHANNEL: Channel,
    Opcode.MESSAGE: Message,
}
_TOP_LEVEL: dict[int, Any] = {
    **_CHUNK_RECORDS,
    Opcode.METADATA: Metadata,
    Opcode.ATTACHMENT: Attachment,
}


def _parse_record(opcode: int, body: bytes, length: int) -> list[Any]:
    """The records held by one whole top-level record (a chunk's inner records)."""
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.CHUNK:
        chunk = Chunk.read(stream)
        data, size = get_chunk_data_stream(chunk, validate_crc=True)  # CRCValidationError
        if size != chunk.uncompressed_size:
            raise ValueError("chunk decompressed to the wrong size")
        return list(inner_records(data.read(size), strict=True))
    reader = _TOP_LEVEL.get(opcode)
    if reader is None:
        return []  # indexes, statistics, unknown opcodes: not needed when scanning
    return [reader.read(stream, length) if opcode == Opcode.MESSAGE else reader.read(stream)]


def inner_records(raw: bytes, strict: bool = False) -> Iterator[Any]:
    """Schema, Channel and Message records of (decompressed) chunk data, while whole.

    ``strict``: the data must hold whole records to its end (ValueError otherwise).
    """
    pos, end = 0, len(raw)
    while pos < end:
        if pos + RECORD_HEAD.size > end:
            break
        opcode, length = RECORD_HEAD.unpack_from(raw, pos)
        start = pos + RECORD_HEAD.size
        if start + length > end:
            break
        pos = start + length
        reader = _CHUNK_RECORDS.get(opcode)
        if reader is None:
            continue
        stream = ReadDataStream(io.BytesIO(raw[start:pos]))
        try:
            rec = reader.read(stream, length) if opcode == Opcode.MESSAGE else reader.read(stream)
        except Exception:
            if strict:
                raise
            return
        yield rec
    if strict and pos != end:
        raise ValueError("chunk data ends inside a record")


def walk(
    f: BinaryIO,
    size: int,
    dmg: Damage,
    start: int = len(MCAP_MAGIC),
    data_end: int | None = None,
    sync: list[int] | None = None,
) -> Iterator[Any]:
    """Walk the top-level records (opcode u8, length u64, body) from offset ``start``.

    A whole record that fails to parse (e.g. a chunk whose compressed data is corrupt)
    is skipped and counted in ``damaged_records``: its length field still frames the
    next record. With ``data_end`` (the start of an intact summary: the file is whole),
    a record with an unknown opcode or a length past ``data_end`` breaks the framing:
    the walk goes on at the next offset of ``sync`` (sorted chunk offsets from the
    summary), the bytes skipped counted in ``lost_bytes``. Without it, a record cut off
    by the end of the file ends the walk (``truncated``); if it is a chunk, the messages
    of its intact compressed prefix are salvaged (``salvaged_messages``). ``lost_bytes``
    counts the bytes past the last whole record and those of damaged records.
    """
    sync = sync or []
    end = size if data_end is None else data_end
    pos = start
    while True:
        f.seek(pos)
        head = f.read(RECORD_HEAD.size) if pos < end else b""
        if len(head) < RECORD_HEAD.size:
            if data_end is None:
                dmg.truncated = True  # no footer: the recording was cut off
                dmg.lost_bytes += len(head)
            return
        opcode, length = RECORD_HEAD.unpack(head)
        whole = length <= end - pos - RECORD_HEAD.size
        if data_end is not None and (not whole or opcode not in _VALID_OPCODES):
            nxt = bisect.bisect_right(sync, pos)  # broken framing: on at the next chunk
            to = sync[nxt] if nxt < len(sync) else end
            dmg.record(pos, to - pos)
            pos = to
            continue
        if not whole:
            if opcode == Opcode.CHUNK:
                yield from _salvage_chunk(f.read(), dmg)
            dmg.truncated = True
            dmg.lost_bytes += max(size - pos, 0)
            return
        body = f.read(length)
        if opcode in (Opcode.FOOTER, Opcode.DATA_END):
            return  # the summary section repeats what the data section held
        try:
            records = _parse_record(opcode, body, length)
        except Exception:
            dmg.record(pos, RECORD_HEAD.size + length)
            pos += RECORD_HEAD.size + length
            continue
        pos += RECORD_HEAD.size + length
        yield from records


def _salvage_chunk(partial: bytes, dmg: Damage) -> Iterator[Any]:
    """Whole records of a chunk cut off by the end of the file.

    Chunk body (MCAP spec "Chunk"): message_start_time u64, message_end_time u64,
    uncompressed_size u64, uncompressed_crc u32, compression (u32-prefixed string),
    records (u64-prefixed bytes). A zstd or lz4 frame decodes block by block, so a
    streaming decompressor returns every block that arrived whole.
    """
    try:
        stream = ReadDataStream(io.BytesIO(partial))
        stream.read(28)
        compression = stream.read_prefixed_string()
        stream.read(8)
        data = partial[stream.count :]
        if compression == "zstd":
            import zstandard

            raw = zstandard.ZstdDecompressor().decompressobj().decompress(data)
        elif compression == "lz4":
            import lz4.frame

            raw = lz4.frame.LZ4FrameDecompressor().decompress(data)
        elif compression == "":
            raw = data
        else:
            return
    except Exception:
        return
    for rec in inner_records(raw):
        if isinstance(rec, Message):
            dmg.salvaged_messages += 1
        yield rec
