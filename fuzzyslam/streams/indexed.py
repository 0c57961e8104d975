"""The indexed backend of ``LogReader``: messages through the MCAP summary and indexes.

For the chunks holding a wanted channel (from the Chunk Index records of the summary),
each chunk is read and decompressed once and only the wanted messages are read, at the
offsets its Message Index records give (MCAP specification, https://mcap.dev/spec:
"Footer", "Chunk", "Message Index", "Chunk Index"). Nothing read from the file is trusted:

- the summary is used only if its CRC (footer ``summary_crc``) matches;
- a chunk must lie inside the data section, start with a Chunk record of the length,
  times, sizes and compression its index gives (else :class:`IndexMismatch`: the
  caller walks the records from the last good chunk on);
- a chunk that fails to decompress or to match its CRC is skipped and counted;
- a Message Index must lie inside the data section, have its channel, a length that
  is a multiple of 16 and entries that point at whole Message records of that channel
  inside the chunk; if not, it is counted and the chunk's records are scanned instead.

Chunks whose time ranges overlap are read together and their messages merged, so the
messages always come in log-time order.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import BinaryIO

from mcap.reader import SeekingReader

from fuzzyslam.streams.recover import MCAP_MAGIC, Damage

_U64 = struct.Struct("<Q")
_U32 = struct.Struct("<I")
_FOOTER = struct.Struct("<BQQQI")  # opcode, length (20), summary start, offsets start, crc
_CHUNK_HEAD = struct.Struct("<BQQQQII")  # opcode, length, start, end, size, crc, compr. len
_MSG = struct.Struct("<BQHIQQ")  # opcode, length, channel id, sequence, log time, publish time
_MSG_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, length, channel id, entries length
_ENTRY = struct.Struct("<QQ")  # log time, offset in the decompressed chunk
OP_CHUNK, OP_MESSAGE_INDEX, OP_MESSAGE, OP_FOOTER = 0x06, 0x07, 0x05, 0x02
COMPRESSIONS = ("", "zstd", "lz4")


class IndexMismatch(Exception):
    """A Chunk Index that does not match the file (or a chunk whose header is damaged)."""

    def __init__(self, resume: int, offset: int) -> None:
        super().__init__(resume, offset)
        self.resume = resume  # a record boundary before the mismatch: walk on from here
        self.offset = offset  # where the index says the chunk is


@dataclass
class ChunkRef:
    offset: int
    length: int
    start: int  # message log times, ns
    end: int
    size: int  # uncompressed
    compressed: int
    compression: str
    message_indexes: dict[int, int]  # channel id -> offset of its Message Index


@dataclass
class Summary:
    """What the summary section of an intact file says."""

    data_end: int  # start of the summary section: the data section ends here
    channels: dict[int, tuple[str, str]]  # channel id -> (topic, schema name)
    chunks: list[ChunkRef]
    counts: dict[str, int]
    start: int  # ns
    end: int
    metadata: dict[str, dict[str, str]]
    attachments: dict[str, bytes]
    # channel id -> its schema's ros2msg definition text (the file's own definitions: two
    # channels of one type name may carry different ones, e.g. bags of two ROS releases)
    definitions: dict[int, str] = field(default_factory=dict)


def schema_text(encoding: str, data: bytes) -> str | None:
    """A Schema record's ros2msg definition text (None: another encoding or not UTF-8).

    Parameters
    ----------
    encoding : str
        The record's schema encoding (``ros2msg`` for ROS 2 messages).
    data : bytes
        Its data.

    Returns
    -------
    str or None
    """
    if encoding != "ros2msg":
        return None
    try:
        return bytes(data).decode("utf-8")
    except UnicodeDecodeError:
        return None


def read_summary(f: BinaryIO, size: int) -> Summary | None:
    """The summary of an intact file, or None (no footer, no summary, CRC mismatch, any
    record that does not parse or an index pointing outside the file)."""
    tail = len(MCAP_MAGIC) + _FOOTER.size
    if size < len(MCAP_MAGIC) + tail:
        return None
    f.seek(size - tail)
    raw = f.read(tail)
    if raw[_FOOTER.size :] != MCAP_MAGIC:
        return None
    op, length, summary_start, _offsets, crc = _FOOTER.unpack_from(raw)
    if op != OP_FOOTER or length != 20 or not len(MCAP_MAGIC) < summary_start < size - tail:
        return None
    f.seek(summary_start)
    summary_bytes = f.read(size - tail - summary_start)
    if crc and zlib.crc32(raw[: _FOOTER.size - 4], zlib.crc32(summary_bytes)) != crc:
        return None
    try:
        f.seek(0)
        reader = SeekingReader(f)
        s = reader.get_summary()
        if s is None:
            return None
        channels = {
            cid: (ch.topic, s.schemas[ch.schema_id].name)
            for cid, ch in s.channels.items()
            if ch.schema_id in s.schemas
        }
        chunks = [
            ChunkRef(
                c.chunk_start_offset,
                c.chunk_length,
                c.message_start_time,
                c.message_end_time,
                c.uncompressed_size,
                c.compressed_size,
                c.compression,
                dict(c.message_index_offsets),
            )
            for c in s.chunk_indexes
        ]
        for c in chunks:
            if not (len(MCAP_MAGIC) <= c.offset and c.offset + c.length <= summary_start):
                return None
        counts: dict[str, int] = {}
        t0 = t1 = 0
        if s.statistics is not None:
            st = s.statistics
            counts = {
                channels[cid][0]: n
                for cid, n in st.channel_message_counts.items()
                if cid in channels
            }
            t0, t1 = st.message_start_time, st.message_end_time
        texts = {sid: schema_text(sc.encoding, sc.data) for sid, sc in s.schemas.items()}
        definitions = {
            cid: texts[ch.schema_id]
            for cid, ch in s.channels.items()
            if texts.get(ch.schema_id) is not None
        }
        metadata = {md.name: dict(md.metadata) for md in reader.iter_metadata()}
        attachments = {a.name: bytes(a.data) for a in reader.iter_attachments()}
    except Exception:  # any record of the summary that does not parse: not usable
        return None
    return Summary(
        summary_start, channels, chunks, counts, t0, t1, metadata, attachments, definitions
    )


def _groups(chunks: list[ChunkRef]) -> Iterator[list[ChunkRef]]:
    """Chunks in log-time order, those whose time ranges overlap grouped together."""
    group: list[ChunkRef] = []
    end = -1
    for c in sorted(chunks, key=lambda c: (c.start, c.offset)):
        if group and c.start >= end:  # a chunk may start at the time the last one ends
            yield group
            group = []
        group.append(c)
        end = max(end, c.end)
    if group:
        yield group


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    import lz4.frame

    return lz4.frame.decompress(data)


RawMessage = tuple[int, int, int, memoryview]  # log time ns, channel id, sequence, payload
_HEAD = _MSG.size  # a Message record's bytes before its payload


RECENT_CHUNKS = 4  # decompressed chunks a reader keeps for its other walks (see below)


def indexed_messages(
    f: BinaryIO,
    summary: Summary,
    wanted: set[int],
    start_ns: int,
    dmg: Damage,
    recent: dict[int, bytes] | None = None,
) -> Iterator[list[RawMessage]]:
    """Raw messages of the channels ``wanted`` logged at or after ``start_ns``, in log-time
    order (ties in file order), in batches (a chunk, or chunks whose time ranges overlap).
    Raises :class:`IndexMismatch` at a chunk that does not match its index.

    ``recent``: the last ``RECENT_CHUNKS`` chunks read whole and intact (by file offset),
    shared by walks of one file that advance together (``run``'s odometry and frames, and
    its sonar rings): a chunk is then read and decompressed once, not once per walk."""
    chunks = [
        c
        for c in summary.chunks  # a chunk without Message Indexes may hold any channel
        if c.end >= start_ns
        and (not c.message_indexes or any(cid in wanted for cid in c.message_indexes))
    ]
    resume = len(MCAP_MAGIC)  # end of the last chunk read whole: a record boundary
    for group in _groups(chunks):
        batches = []
        for k, c in enumerate(group):
            data = recent.get(c.offset) if recent is not None else None
            if data is None:
                data = _chunk_data(f, c, resume, dmg)
                if data is None:
                    continue
                if recent is not None:
                    recent[c.offset] = data
                    while len(recent) > RECENT_CHUNKS:
                        del recent[next(iter(recent))]
            view = memoryview(data)
            batches.append(
                [
                    (t, k, off, cid, seq, view[off + _HEAD : off + 9 + length])
                    for t, off, cid, seq, length in _entries(
                        f, c, data, wanted, summary.data_end, dmg
                    )
                    if t >= start_ns
                ]
            )
        found = [e for b in batches for e in b]
        if len(batches) > 1:
            found.sort(key=lambda e: e[:3])
        yield [(t, cid, seq, payload) for t, _k, _off, cid, seq, payload in found]
        resume = max(c.offset + c.length for c in group)


def _chunk_data(f: BinaryIO, c: ChunkRef, resume: int, dmg: Damage) -> bytes | None:
    """The decompressed records of chunk ``c``; None if its data is corrupt (counted).
    IndexMismatch if the record at its offset is not the chunk its index describes."""
    f.seek(c.offset)
    raw = f.read(c.length)
    head = _CHUNK_HEAD.size
    if len(raw) != c.length or c.length < head:
        raise IndexMismatch(resume, c.offset)
    op, length, t0, t1, size, crc, clen = _CHUNK_HEAD.unpack_from(raw)
    pos = head + clen
    if (
        op != OP_CHUNK
        or length != c.length - 9
        or (t0, t1, size) != (c.start, c.end, c.size)
        or pos + 8 > c.length
        or raw[head:pos] != c.compression.encode()
        or c.compression not in COMPRESSIONS
        or _U64.unpack_from(raw, pos)[0] != c.length - pos - 8
        or c.length - pos - 8 != c.compressed
    ):
        raise IndexMismatch(resume, c.offset)
    try:
        data = _decompress(raw[pos + 8 :], c.compression, size)
        if len(data) != size or (crc and zlib.crc32(data) != crc):
            raise ValueError("chunk CRC mismatch")
    except Exception:  # corrupt compressed data: the chunk is lost, framing is intact
        dmg.record(c.offset, c.length)
        return None
    return data


def _entries(
    f: BinaryIO, c: ChunkRef, data: bytes, wanted: set[int], data_end: int, dmg: Damage
) -> list[tuple[int, int, int, int, int]]:
    """(log time, offset, channel id, sequence, length) of the wanted messages of a chunk,
    from its Message Index records, or from a scan of its records if one is damaged."""
    if not c.message_indexes:  # written without Message Indexes: scan the records
        return _scan(data, wanted)
    out: list[tuple[int, int, int, int, int]] = []
    for cid, off in c.message_indexes.items():
        if cid not in wanted:
            continue
        got = _index_entries(f, cid, off, c.offset + c.length, data, data_end)
        if isinstance(got, int):  # damaged: counted, the chunk's records scanned instead
            dmg.record(off, got)
            return _scan(data, wanted)
        out.extend(got)
    out.sort()
    return out


def _index_entries(
    f: BinaryIO, cid: int, off: int, lo: int, data: bytes, data_end: int
) -> list[tuple[int, int, int, int, int]] | int:
    """Entries of the Message Index at ``off`` checked against the chunk data (``lo``: the
    chunk's end), or, if it is damaged, the number of its bytes inside the data section."""
    if not lo <= off <= data_end - _MSG_INDEX_HEAD.size:
        return 0
    f.seek(off)
    head = f.read(_MSG_INDEX_HEAD.size)
    op, length, ch, n = _MSG_INDEX_HEAD.unpack(head)
    if op != OP_MESSAGE_INDEX or ch != cid or n % 16 or length != n + 6:
        return min(9 + length, data_end - off)
    if off + 9 + length > data_end:
        return data_end - off
    body = f.read(n)
    out = []
    size = len(data)
    for t, o in _ENTRY.iter_unpack(body):
        if o + _MSG.size > size:
            return 9 + length
        op, rlen, ch, seq, log_time, _pub = _MSG.unpack_from(data, o)
        if op != OP_MESSAGE or ch != cid or log_time != t or rlen < 22 or o + 9 + rlen > size:
            return 9 + length
        out.append((t, o, cid, seq, rlen))
    return out


def _scan(data: bytes, wanted: set[int]) -> list[tuple[int, int, int, int, int]]:
    """(log time, offset, channel id, sequence, length) of the wanted Message records of
    decompressed chunk data (whole records, as the chunk's CRC vouches)."""
    out = []
    pos, size = 0, len(data)
    while pos + 9 <= size:
        op, length = struct.unpack_from("<BQ", data, pos)
        if pos + 9 + length > size:
            break
        if op == OP_MESSAGE and length >= 22:
            _op, _len, cid, seq, t, _pub = _MSG.unpack_from(data, pos)
            if cid in wanted:
                out.append((t, pos, cid, seq, length))
        pos += 9 + length
    out.sort()
    return out


def chunk_offsets(summary: Summary) -> list[int]:
    """Sorted chunk offsets (re-synchronisation points of the recovering walk)."""
    return sorted(c.offset for c in summary.chunks)
