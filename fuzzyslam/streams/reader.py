"""MCAP log reader: ROS 2 messages decoded with rosbags, tolerant of truncated files.

A complete file is read through its summary and index, in log-time order. A file
whose summary is missing or damaged (a robot that lost power mid-recording) is
read record by record, in file order, as far as it is intact: a whole record that
fails to parse (a corrupt chunk) is skipped and counted, and a chunk cut off by the
end of the file gives the messages of its intact compressed blocks (zstd and lz4
frames decode block by block). ``damage()`` says how much was lost (``truncated``,
``lost_bytes``, ``salvaged_messages``, ``damaged_records``, ``undecodable``). A file
that is not MCAP is one clear InputError.
"""

from __future__ import annotations

import io
import json
import os
import struct
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any, BinaryIO

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Chunk, Message, Metadata, Schema
from mcap.stream_reader import get_chunk_data_stream

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import check_input_file
from fuzzyslam.streams.typestore import deserialize, normalise_typename, typestore

MCAP_MAGIC = b"\x89MCAP0\r\n"


_RECORD_HEAD = struct.Struct("<BQ")


def _parse_record(opcode: int, body: bytes, length: int) -> list[Any]:
    """The records held by one whole top-level record (a chunk's inner records)."""
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.CHUNK:
        chunk = Chunk.read(stream)
        data, size = get_chunk_data_stream(chunk, validate_crc=True)  # CRCValidationError
        if size != chunk.uncompressed_size:
            raise ValueError("chunk decompressed to the wrong size")
        return list(_inner_records(data.read(size), strict=True))
    reader = _TOP_LEVEL.get(opcode)
    if reader is None:
        return []  # indexes, statistics, unknown opcodes: not needed when scanning
    return [reader.read(stream, length) if opcode == Opcode.MESSAGE else reader.read(stream)]


def _inner_records(raw: bytes, strict: bool = False) -> Iterator[Any]:
    """Schema, Channel and Message records of (decompressed) chunk data, while whole.

    ``strict``: the data must hold whole records to its end (ValueError otherwise).
    """
    pos, end = 0, len(raw)
    while pos < end:
        if pos + _RECORD_HEAD.size > end:
            break
        opcode, length = _RECORD_HEAD.unpack_from(raw, pos)
        start = pos + _RECORD_HEAD.size
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


@dataclass
class Damage:
    """What a record scan found wrong with a file (see ``LogReader``)."""

    truncated: bool = False
    lost_bytes: int = 0
    damaged_records: int = 0
    salvaged_messages: int = 0


@dataclass(frozen=True)
class LogMessage:
    """One decoded message: topic, log time (s), ROS type name and the message object."""

    topic: str
    t: float
    typename: str
    msg: Any


class LogReader:
    """Read a ROS 2 MCAP recording.

    Attributes after opening: ``topics`` (topic -> type name), ``counts`` (topic ->
    message count, when the summary is intact), ``start``/``end`` (s), ``metadata``
    (name -> dict), ``attachments`` (name -> bytes), and what a damaged file lost:
    ``truncated``, ``lost_bytes``, ``salvaged_messages``, ``damaged_records``,
    ``undecodable`` (``damage()`` returns them as a dict for a JSON summary).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = check_input_file(path, "log")
        self.size = self.path.stat().st_size
        with open(self.path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
        if head != MCAP_MAGIC:
            raise InputError(self.path, "not an MCAP file (bad magic bytes)")
        self.topics: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.attachments: dict[str, bytes] = {}
        self.start = 0.0
        self.end = 0.0
        self.truncated = False
        self.lost_bytes = 0
        self.damaged_records = 0
        self.salvaged_messages = 0
        self.undecodable = 0
        self._summary_ok = self._read_summary()
        if not self._summary_ok:
            self._scan_stream()

    # -- opening ------------------------------------------------------------------

    def _read_summary(self) -> bool:
        try:
            with open(self.path, "rb") as f:
                reader = SeekingReader(f)
                summary = reader.get_summary()
                if summary is None:
                    return False
                for ch in summary.channels.values():
                    schema = summary.schemas.get(ch.schema_id)
                    if schema is not None:
                        self.topics[ch.topic] = normalise_typename(schema.name)
                if summary.statistics is not None:
                    st = summary.statistics
                    by_id = summary.channels
                    self.counts = {
                        by_id[cid].topic: n
                        for cid, n in st.channel_message_counts.items()
                        if cid in by_id
                    }
                    self.start = st.message_start_time / 1e9
                    self.end = st.message_end_time / 1e9
                for md in reader.iter_metadata():
                    self.metadata[md.name] = dict(md.metadata)
                for att in reader.iter_attachments():
                    self.attachments[att.name] = bytes(att.data)
            return True
        except (McapError, ValueError, EOFError, OSError, KeyError, IndexError, AssertionError):
            self.topics, self.counts, self.metadata, self.attachments = {}, {}, {}, {}
            return False
        except Exception:
            self.topics, self.counts, self.metadata, self.attachments = {}, {}, {}, {}
            return False

    def _records(self, damage: Damage | None = None) -> Iterator[Any]:
        """Records of the file in file order, as far as it is intact (``_walk``)."""
        with open(self.path, "rb") as f:
            yield from self._walk(f, damage if damage is not None else Damage())

    def _walk(self, f: BinaryIO, dmg: Damage) -> Iterator[Any]:
        """Walk the top-level records (opcode u8, length u64, body; MCAP spec "Records").

        A whole record that fails to parse (e.g. a chunk whose compressed data is
        corrupt) is skipped and counted in ``damaged_records``: its length field still
        frames the next record. A record cut off by the end of the file ends the walk;
        if it is a chunk, the messages of its intact compressed prefix are salvaged
        (``_salvage_chunk``, counted in ``salvaged_messages``). ``lost_bytes`` counts
        the bytes past the last whole record (the cut-off tail, partly salvaged) and
        the bytes of damaged records.
        """
        f.seek(len(MCAP_MAGIC))
        pos = len(MCAP_MAGIC)
        while True:
            head = f.read(_RECORD_HEAD.size)
            if len(head) < _RECORD_HEAD.size:
                dmg.truncated = True  # no footer: the recording was cut off
                dmg.lost_bytes += len(head)
                return
            opcode, length = _RECORD_HEAD.unpack(head)
            body = f.read(length) if length <= self.size - pos - _RECORD_HEAD.size else None
            if body is None or len(body) < length:
                if opcode == Opcode.CHUNK:
                    f.seek(pos + _RECORD_HEAD.size)
                    yield from self._salvage_chunk(f.read(), dmg)
                dmg.truncated = True
                dmg.lost_bytes += max(self.size - pos, 0)
                return
            pos += _RECORD_HEAD.size + length
            if opcode in (Opcode.FOOTER, Opcode.DATA_END):
                return  # the summary section repeats what the data section held
            try:
                records = _parse_record(opcode, body, length)
            except Exception:
                dmg.damaged_records += 1
                dmg.lost_bytes += _RECORD_HEAD.size + length
                continue
            yield from records

    def _salvage_chunk(self, partial: bytes, dmg: Damage) -> Iterator[Any]:
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
        for rec in _inner_records(raw):
            if isinstance(rec, Message):
                dmg.salvaged_messages += 1
            yield rec

    def _scan_stream(self) -> None:
        schemas: dict[int, str] = {}
        t0, t1, n = None, None, 0
        counts: dict[str, int] = {}
        channels: dict[int, str] = {}
        dmg = Damage()
        for rec in self._records(dmg):
            if isinstance(rec, Schema):
                schemas[rec.id] = normalise_typename(rec.name)
            elif isinstance(rec, Channel):
                channels[rec.id] = rec.topic
                if rec.schema_id in schemas:
                    self.topics[rec.topic] = schemas[rec.schema_id]
            elif isinstance(rec, Message):
                topic = channels.get(rec.channel_id)
                if topic is not None:
                    counts[topic] = counts.get(topic, 0) + 1
                t0 = rec.log_time if t0 is None else min(t0, rec.log_time)
                t1 = rec.log_time if t1 is None else max(t1, rec.log_time)
                n += 1
            elif isinstance(rec, Metadata):
                self.metadata[rec.name] = dict(rec.metadata)
            elif isinstance(rec, Attachment):
                self.attachments[rec.name] = bytes(rec.data)
        # no usable summary: the file is damaged even if every record parsed
        self.truncated = True
        self.lost_bytes = dmg.lost_bytes
        self.damaged_records = dmg.damaged_records
        self.salvaged_messages = dmg.salvaged_messages
        self.counts = counts
        self.start = (t0 or 0) / 1e9
        self.end = (t1 or 0) / 1e9
        if n == 0 and not self.topics:
            raise InputError(self.path, "MCAP file holds no readable messages (damaged or empty)")

    # -- queries ------------------------------------------------------------------

    def mark_damaged(self, nbytes: int) -> None:
        """Count one damaged record of ``nbytes`` found by another reader of this file
        (e.g. an indexed reader that met a chunk failing its CRC and skipped it)."""
        self.damaged_records += 1
        self.lost_bytes += int(nbytes)

    def damage(self) -> dict[str, Any]:
        """How much of the file was lost, for a stage's JSON summary.

        ``truncated``: the summary/footer is missing or damaged (the file was read by a
        record scan); ``lost_bytes``: bytes past the last whole record (a cut-off tail,
        partly salvaged) and of damaged records; ``salvaged_messages``: messages recovered
        from a cut-off chunk;
        ``damaged_records``: whole records that failed to parse and were skipped;
        ``undecodable``: messages skipped because their payload failed to decode.
        """
        return {
            "truncated": bool(self.truncated),
            "lost_bytes": int(self.lost_bytes),
            "lost_fraction": round(self.lost_bytes / self.size, 6) if self.size else 0.0,
            "salvaged_messages": int(self.salvaged_messages),
            "damaged_records": int(self.damaged_records),
            "undecodable": int(self.undecodable),
        }

    def has(self, topic: str) -> bool:
        return topic in self.topics

    def require(self, topics: Iterable[str], option: str = "the config's 'topics' section") -> None:
        """Raise InputError naming the missing topics and where to map them."""
        missing = [t for t in topics if t not in self.topics]
        if missing:
            have = ", ".join(sorted(self.topics)) or "none"
            raise InputError(
                self.path,
                f"missing stream(s) {', '.join(missing)} "
                f"(set them in {option}; the log has: {have})",
            )

    def json_metadata(self, name: str) -> Any | None:
        """Decode a metadata record written by LogWriter.json_metadata, or None."""
        md = self.metadata.get(name)
        if md is None or "json" not in md:
            return None
        try:
            return json.loads(md["json"])
        except json.JSONDecodeError:
            raise InputError(self.path, f"metadata '{name}' is not valid JSON") from None

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[LogMessage]:
        """Decoded messages of ``topics`` (all if None) in log-time order.

        On a truncated file, messages come in file order, as far as the file is intact.
        Chunk CRCs are checked: if an indexed file holds a damaged chunk, reading goes on
        from the last message yielded by a record walk that skips (and counts) the
        damaged chunk. Messages that fail to decode are skipped and counted in
        ``undecodable``.
        """
        wanted = set(topics) if topics is not None else None
        if not self._summary_ok:
            yield from self._walk_messages(wanted, Damage())
            return
        last_ns, at_last = -1, set()
        with open(self.path, "rb") as f:
            reader = SeekingReader(f, validate_crcs=True)
            try:
                for schema, channel, message in reader.iter_messages(
                    topics=sorted(wanted) if wanted is not None else None, log_time_order=True
                ):
                    if message.log_time != last_ns:
                        last_ns, at_last = message.log_time, set()
                    at_last.add((message.channel_id, message.sequence))
                    if schema is None:
                        continue
                    out = self._decode(channel.topic, schema.name, message)
                    if out is not None:
                        yield out
                return
            except Exception:  # a damaged chunk (CRC, zstd, short read): walk on from here
                pass
        dmg = Damage()
        yield from self._walk_messages(wanted, dmg, last_ns, at_last)
        self.damaged_records = max(self.damaged_records, dmg.damaged_records, 1)
        self.lost_bytes = max(self.lost_bytes, dmg.lost_bytes)

    def _walk_messages(
        self,
        wanted: set[str] | None,
        dmg: Damage,
        from_ns: int = -1,
        seen: set[tuple[int, int]] | frozenset = frozenset(),
    ) -> Iterator[LogMessage]:
        """Messages of the record walk in file order, those before ``from_ns`` (log time)
        and the ``seen`` (channel id, sequence) at ``from_ns`` left out."""
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        for rec in self._records(dmg):
            if isinstance(rec, Schema):
                schemas[rec.id] = rec.name
            elif isinstance(rec, Channel):
                if rec.schema_id in schemas:
                    channels[rec.id] = (rec.topic, schemas[rec.schema_id])
            elif isinstance(rec, Message):
                if rec.log_time < from_ns or (
                    rec.log_time == from_ns and (rec.channel_id, rec.sequence) in seen
                ):
                    continue
                ch = channels.get(rec.channel_id)
                if ch is None or (wanted is not None and ch[0] not in wanted):
                    continue
                out = self._decode(ch[0], ch[1], rec)
                if out is not None:
                    yield out

    def _decode(self, topic: str, schema_name: str, message: Any) -> LogMessage | None:
        typename = normalise_typename(schema_name)
        if typename not in typestore().types:
            self.undecodable += 1
            return None
        try:
            msg = deserialize(message.data, typename)
        except Exception:
            self.undecodable += 1
            return None
        return LogMessage(topic, message.log_time / 1e9, typename, msg)
