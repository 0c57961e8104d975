"""Fast indexed reading of a few topics of an MCAP file.

``LogReader.messages`` parses every record of every chunk it opens (all 16 sonar
topics and ground truth too), which dominated the run time. This reader uses the
MCAP summary instead: for each chunk holding a wanted channel it decompresses the
chunk once and reads only the wanted messages at the offsets given by the chunk's
MessageIndex records (MCAP specification, "Chunk", "Message Index", "Chunk Index":
https://mcap.dev/spec). It returns None (the caller falls back to ``LogReader``)
when the file has no usable summary or its chunks overlap in time, so log-time
order is always kept. JointState, Image and Range, the messages the filter reads most,
are decoded by small CDR readers (the rest by rosbags).
"""

from __future__ import annotations

import itertools
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from mcap.reader import SeekingReader

from fuzzyslam.streams.reader import LogMessage, LogReader
from fuzzyslam.streams.typestore import deserialize, normalise_typename, typestore

_U64 = struct.Struct("<Q")
_U32 = struct.Struct("<I")
_STAMP_FRAME = struct.Struct("<iII")  # header stamp sec, nanosec; frame_id length
JOINT_STATE = "sensor_msgs/msg/JointState"
_MSG = struct.Struct("<BQHIQQ")  # opcode, length, channel id, sequence, log time, publish time
_MSG_INDEX_ENTRY = struct.Struct("<QQ")


@dataclass(slots=True)
class _Stamp:
    sec: int
    nanosec: int


@dataclass(slots=True)
class _Header:
    stamp: _Stamp
    frame_id: str


@dataclass(slots=True)
class JointStateLite:
    """The fields of sensor_msgs/JointState the filter reads (velocity, effort skipped)."""

    header: _Header
    name: list[str]
    position: np.ndarray


def decode_joint_state(buf: bytes | memoryview) -> JointStateLite:
    """Decode a little-endian CDR JointState up to ``position`` (OMG CDR: primitives are
    aligned to their size, counted from the end of the 4-byte encapsulation header).

    rosbags' generic decoder costs ~30 us a message; this is the hot path at 20 Hz.
    """
    o = 4
    header, p = _read_header(buf, o)
    p += -p % 4
    count = _U32.unpack_from(buf, o + p)[0]
    p += 4
    names = []
    for _ in range(count):
        p += -p % 4
        n = _U32.unpack_from(buf, o + p)[0]
        names.append(str(buf[o + p + 4 : o + p + 3 + n], "utf-8"))
        p += 4 + n
    p += -p % 4
    count = _U32.unpack_from(buf, o + p)[0]
    p += 4
    p += -p % 8
    pos = np.frombuffer(buf, dtype="<f8", count=count, offset=o + p).copy()
    return JointStateLite(header, names, pos)


@dataclass(slots=True)
class ImageLite:
    """sensor_msgs/Image fields (``data`` a read-only uint8 view of the chunk, no copy)."""

    header: _Header
    height: int
    width: int
    encoding: str
    is_bigendian: int
    step: int
    data: np.ndarray


def _read_header(buf, o: int) -> tuple[_Header, int]:
    """std_msgs/Header at CDR offset 0 (after the 4-byte encapsulation at ``o``); returns
    the header and the next offset relative to ``o``."""
    sec, nsec, n = _STAMP_FRAME.unpack_from(buf, o)
    frame = str(buf[o + 12 : o + 12 + n - 1], "utf-8")
    return _Header(_Stamp(sec, nsec), frame), 12 + n


def decode_image(buf: bytes | memoryview) -> ImageLite:
    """Decode a little-endian CDR sensor_msgs/Image (header, height, width, encoding,
    is_bigendian, step, data)."""
    o = 4
    header, p = _read_header(buf, o)
    p += -p % 4
    height, width, n = struct.unpack_from("<III", buf, o + p)
    encoding = bytes(buf[o + p + 12 : o + p + 11 + n]).decode()
    p += 12 + n
    big = buf[o + p]
    p += 1
    p += -p % 4
    step, count = struct.unpack_from("<II", buf, o + p)
    p += 8
    data = np.frombuffer(buf, dtype=np.uint8, count=count, offset=o + p)
    return ImageLite(header, height, width, encoding, big, step, data)


@dataclass(slots=True)
class RangeLite:
    """sensor_msgs/Range fields (the sonar rings: 16 messages per ring)."""

    header: _Header
    radiation_type: int
    field_of_view: float
    min_range: float
    max_range: float
    range: float


_RANGE_TAIL = struct.Struct("<ffff")


def decode_range(buf: bytes | memoryview) -> RangeLite:
    """Decode a little-endian CDR sensor_msgs/Range (header, radiation_type u8, then four
    float32 aligned to 4: field_of_view, min_range, max_range, range)."""
    o = 4
    header, p = _read_header(buf, o)
    kind = buf[o + p]
    p += 1
    p += -p % 4
    fov, lo, hi, r = _RANGE_TAIL.unpack_from(buf, o + p)
    return RangeLite(header, kind, fov, lo, hi, r)


# fast decoders of the frequent types; called only on little-endian CDR
_DECODERS = {
    JOINT_STATE: decode_joint_state,
    "sensor_msgs/msg/Image": decode_image,
    "sensor_msgs/msg/Range": decode_range,
}


def _decompress(data: bytes, compression: str, size: int) -> bytes:
    if compression == "":
        return data
    if compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(data)
    raise ValueError(f"unknown chunk compression {compression!r}")


def indexed_messages(
    reader: LogReader, topics: list[str], start: float | None = None
) -> Iterator[LogMessage] | None:
    """Messages of ``topics`` in log-time order via the chunk indexes, or None if not possible.

    ``start`` (s): skip messages logged before it (chunks ending before it are not read)."""
    if not getattr(reader, "_summary_ok", False):
        return None
    with open(reader.path, "rb") as f:
        try:
            summary = SeekingReader(f).get_summary()
        except Exception:
            return None
    if summary is None or not summary.chunk_indexes:
        return None
    wanted = {
        cid: (ch.topic, summary.schemas[ch.schema_id].name)
        for cid, ch in summary.channels.items()
        if ch.topic in set(topics) and ch.schema_id in summary.schemas
    }
    chunks = sorted(
        (c for c in summary.chunk_indexes if any(cid in wanted for cid in c.message_index_offsets)),
        key=lambda c: (c.message_start_time, c.chunk_start_offset),
    )
    for a, b in itertools.pairwise(chunks):
        if b.message_start_time < a.message_end_time:
            return None
    start_ns = -1 if start is None else round(start * 1e9)
    chunks = [c for c in chunks if c.message_end_time >= start_ns]
    return _iterate(reader, wanted, chunks, start_ns)


def _iterate(
    reader: LogReader, wanted: dict, chunks: list, start_ns: int = -1
) -> Iterator[LogMessage]:
    types = typestore().types
    # per channel: topic, type name, decoder of little-endian CDR (or None: rosbags)
    chan = {}
    for cid, (topic, schema) in wanted.items():
        typename = normalise_typename(schema)
        if typename in types:
            chan[cid] = (topic, typename, _DECODERS.get(typename))
    with open(reader.path, "rb") as f:
        for c in chunks:
            f.seek(c.chunk_start_offset)
            raw = f.read(c.chunk_length)
            # Chunk record: opcode u8, length u64, start u64, end u64, size u64, crc u32,
            # compression (u32 length + str), records (u64 length + bytes)
            pos = 1 + 8 + 8 + 8
            size = _U64.unpack_from(raw, pos)[0]
            pos += 8 + 4
            clen = struct.unpack_from("<I", raw, pos)[0]
            compression = raw[pos + 4 : pos + 4 + clen].decode()
            pos += 4 + clen
            rlen = _U64.unpack_from(raw, pos)[0]
            pos += 8
            try:
                data = _decompress(raw[pos : pos + rlen], compression, size)
                crc = _U32.unpack_from(raw, 1 + 8 + 8 + 8 + 8)[0]
                if len(data) != size or (crc and zlib.crc32(data) != crc):
                    raise ValueError("chunk CRC mismatch")
            except Exception:  # a damaged chunk: skipped and counted (LogReader.damage)
                reader.mark_damaged(c.chunk_length)
                continue
            entries: list[tuple[int, int]] = []
            for cid, off in c.message_index_offsets.items():
                if cid not in wanted:
                    continue
                f.seek(off)
                head = f.read(1 + 8 + 2 + 4)
                n = struct.unpack_from("<I", head, 11)[0]
                body = f.read(n)
                entries.extend(_MSG_INDEX_ENTRY.iter_unpack(body))
            entries.sort()
            view = memoryview(data)
            for t_ns, off in entries:
                if t_ns < start_ns:
                    continue
                try:
                    _op, length, cid, _seq, log_time, _pub = _MSG.unpack_from(data, off)
                    topic, typename, fast = chan[cid]
                except (KeyError, struct.error):  # a damaged entry, or a type not known
                    reader.undecodable += 1
                    continue
                payload = view[off + _MSG.size : off + 9 + length]
                try:
                    if fast is not None and payload[1] == 1:  # little-endian CDR
                        msg = fast(payload)
                    else:
                        msg = deserialize(payload, typename)
                except Exception:
                    reader.undecodable += 1
                    continue
                yield LogMessage(topic, log_time / 1e9, typename, msg)
