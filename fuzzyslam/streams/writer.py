"""MCAP log writer: ROS 2 profile, ros2msg schemas, CDR messages, zstd chunks; the message
definitions, and the rosbag2 record's ``ROS_DISTRO``, of one ROS 2 distribution (the
config's ``output.ros_distro``: streams/distro.py).

Writes to a temporary name and renames onto the target only when the file is finished,
closed and flushed to the disk without error (fileio.atomic_path), so a failed or
interrupted command -- also a disk that fills up, or Ctrl-C inside ``finish`` -- leaves
the previous file, if any, as it was.
"""

from __future__ import annotations

import contextlib
import json
import os
import struct
import sys
import zlib
from collections.abc import Collection
from pathlib import Path
from typing import Any

import zstandard
from mcap.opcode import Opcode
from mcap.records import Chunk, ChunkIndex, MessageIndex
from mcap.writer import CompressionType, IndexType, Writer

from fuzzyslam import __version__
from fuzzyslam.fileio import atomic_path
from fuzzyslam.stamps import to_ns
from fuzzyslam.streams.distro import DEFAULT_ROS_DISTRO, check_distro
from fuzzyslam.streams.topics import Topics
from fuzzyslam.streams.typestore import msgdef, normalise_typename, serialize

_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, record length, channel, sequence, 2 times
_MESSAGE_OPCODE = 0x05


class _PackedIndex(MessageIndex):
    """A chunk's Message Index record written with one struct pack for all its (log time,
    offset) entries (mcap's writes each number on its own: the same bytes)."""

    def write(self, stream) -> None:
        """The record: opcode 0x04, length, channel id, entries' byte count, entries."""
        n = len(self.records)
        stream.start_record(Opcode.MESSAGE_INDEX)
        stream.write(struct.pack(f"<HI{2 * n}Q", self.channel_id, 16 * n,
                                 *(v for entry in self.records for v in entry)))  # fmt: skip
        stream.finish_record()


# zstd level of the chunks: 1 compresses a simulated log's 103 MB of chunks in 0.12 s
# into 42.3 MB, mcap's default 3 in 0.49 s into 43.7 MB (the camera frames' noise does not
# compress better with more effort), and its chunks decompress 1.35x faster; the
# messages, and so everything read from a log, are the same at any level
ZSTD_LEVEL = 1


class _LeanWriter(Writer):
    """mcap's Writer with a lean ``add_message``: the message record packed in one struct
    call straight into the open chunk, the statistics and the chunk's message index kept
    exactly as ``Writer.add_message`` keeps them (the same bytes: tests/test_fast_paths.py
    writes both). The rest (schemas, channels, chunks, summary) is mcap's own. When this
    mcap has other internals, the plain ``add_message`` is used."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        # name-mangled internals of mcap 1.x's Writer and ChunkBuilder
        self._stats = getattr(self, "_Writer__statistics", None)
        self._chunks = getattr(self, "_Writer__chunk_builder", None)
        self._limit = getattr(self, "_Writer__chunk_size", None)
        self._finalize = getattr(self, "_Writer__finalize_chunk", None)
        parts = ("record_writer", "message_indices", "num_messages", "message_start_time")
        self.lean = None not in (self._stats, self._chunks, self._limit, self._finalize) and all(
            hasattr(self._chunks, a) for a in parts
        )
        self._zstd = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
        private = ("compression", "record_builder", "stream", "enable_crcs", "index_types",
                   "chunk_indices", "flush")  # fmt: skip
        self._level_chunks = self.lean and all(hasattr(self, f"_Writer__{a}") for a in private)

    def _Writer__finalize_chunk(self) -> None:
        """mcap 1.x's ``Writer.__finalize_chunk`` (which ``finish`` and a full chunk call)
        with a zstd chunk compressed at ``ZSTD_LEVEL``: the same Chunk, Message Index and
        Chunk Index records as mcap writes, but for the compressed bytes. With other
        internals or another compression, mcap's own."""
        if not self._level_chunks or self._Writer__compression != CompressionType.ZSTD:
            Writer._Writer__finalize_chunk(self)
            return
        cb, records = self._chunks, self._Writer__record_builder
        if cb.num_messages == 0:
            return
        self._stats.chunk_count += 1
        chunk_data = cb.end()
        compressed = self._zstd.compress(chunk_data)
        chunk = Chunk(
            compression="zstd",
            data=compressed,
            message_start_time=cb.message_start_time,
            message_end_time=cb.message_end_time,
            uncompressed_crc=zlib.crc32(chunk_data) if self._Writer__enable_crcs else 0,
            uncompressed_size=len(chunk_data),
        )
        self._Writer__flush()
        start = self._Writer__stream.tell()
        chunk.write(records)
        index = ChunkIndex(
            message_start_time=chunk.message_start_time,
            message_end_time=chunk.message_end_time,
            chunk_start_offset=start,
            chunk_length=records.count,
            message_index_offsets={},
            message_index_length=0,
            compression=chunk.compression,
            compressed_size=len(compressed),
            uncompressed_size=chunk.uncompressed_size,
        )
        self._Writer__flush()
        index_start = self._Writer__stream.tell()
        if self._Writer__index_types & IndexType.MESSAGE:
            for cid, message_index in cb.message_indices.items():
                index.message_index_offsets[cid] = index_start + records.count
                message_index.write(records)
        index.message_index_length = records.count
        self._Writer__flush()
        self._Writer__chunk_indices.append(index)
        cb.reset()

    def add_message(
        self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0
    ) -> None:
        """``Writer.add_message`` (chunked), written out for one message."""
        if not self.lean:
            super().add_message(channel_id, log_time, data, publish_time, sequence)
            return
        self._add_lean((channel_id,), log_time, (data,), (sequence,), publish_time)

    def add_messages(
        self, channel_ids: list[int], log_time: int, datas: list[bytes], sequences: list[int]
    ) -> None:
        """:meth:`add_message` of several messages of one log (and publish) time, in order:
        the same records, statistics and indices, the bookkeeping of the time once."""
        if not self.lean:
            for cid, data, seq in zip(channel_ids, datas, sequences, strict=True):
                super().add_message(cid, log_time, data, log_time, seq)
            return
        self._add_lean(channel_ids, log_time, datas, sequences, log_time)

    def _add_lean(self, channel_ids, log_time: int, datas, sequences, publish_time: int) -> None:
        """The chunked ``Writer.add_message``'s records, statistics and indices for
        messages of one log and publish time, in order (mcap 1.x's internals)."""
        st, cb, pack, limit = self._stats, self._chunks, _MESSAGE_HEAD.pack, self._limit
        counts = st.channel_message_counts
        for cid, data, seq in zip(channel_ids, datas, sequences, strict=True):
            if st.message_count == 0:
                st.message_start_time = log_time
            else:
                st.message_start_time = min(log_time, st.message_start_time)
            st.message_end_time = max(log_time, st.message_end_time)
            counts[cid] += 1
            st.message_count += 1
            if cb.num_messages == 0:
                cb.message_start_time = log_time
            else:
                cb.message_start_time = min(cb.message_start_time, log_time)
            cb.message_end_time = max(cb.message_end_time, log_time)
            index = cb.message_indices.get(cid)
            if index is None:
                index = cb.message_indices[cid] = _PackedIndex(channel_id=cid, records=[])
            rec = cb.record_writer
            index.records.append((log_time, rec.count))
            cb.num_messages += 1
            rec.write(pack(_MESSAGE_OPCODE, 22 + len(data), cid, seq, log_time, publish_time))
            rec.write(data)
            if rec.count > limit:
                self._finalize()


ROS_DISTRO = DEFAULT_ROS_DISTRO  # the distribution written unless one is given
# QoS durability and reliability as rosbag2 records them (rmw's enum values)
_RELIABLE, _TRANSIENT_LOCAL, _VOLATILE = 1, 1, 2
_INFINITE = "{sec: 2147483647, nsec: 4294967295}"  # rosbag2's record of an unset duration


def offered_qos(latched: bool) -> str:
    """The ``offered_qos_profiles`` channel metadata of the MCAP ros2 profile: the QoS of
    the topic's one publisher as rosbag2 records it (YAML, rmw's enum values, read by
    every ROS 2 release), which ``ros2 bag play`` offers again. A latched topic
    (``/tf_static``, a map) is reliable and transient local, so that a listener that
    joins later (tf2's static listener, RViz's map display, which ask for transient
    local) still gets it; the others reliable and volatile, ROS 2's default.

    Parameters
    ----------
    latched : bool
        The topic is published once and kept for late subscribers.

    Returns
    -------
    str
        A YAML list of one profile.
    """
    durability = _TRANSIENT_LOCAL if latched else _VOLATILE
    return (
        f"- history: 3\n  depth: 0\n  reliability: {_RELIABLE}\n  durability: {durability}\n"
        f"  deadline: {_INFINITE}\n  lifespan: {_INFINITE}\n  liveliness: 1\n"
        f"  liveliness_lease_duration: {_INFINITE}\n  avoid_ros_namespace_conventions: false"
    )


class LogWriter:
    """Write ROS 2 messages to one MCAP file.

    Every channel carries the QoS its publisher offered (:func:`offered_qos`): the
    ``latched`` topics (default ``Topics().latched()``, the default names) transient
    local, the others volatile. ``ros_distro`` (default Humble) is the distribution
    whose definitions the schemas hold and whose name the rosbag2 metadata record
    holds; messages given as objects are serialised by its definitions, those given as
    bytes must follow them (``streams/cdr_encode.py``'s encoders take the distribution).

    >>> with LogWriter("out.mcap", latched={"/tf_static"}) as w:   # doctest: +SKIP
    ...     w.write("/sonar/s00", "sensor_msgs/msg/Range", msg, t)
    """

    def __init__(
        self,
        path: str | os.PathLike,
        chunk_size: int = 1024 * 1024,
        latched: Collection[str] | None = None,
        ros_distro: str = ROS_DISTRO,
    ) -> None:
        self.path = Path(path)
        self.ros_distro = check_distro(ros_distro)
        self.chunk_size = chunk_size
        self.latched = Topics().latched() if latched is None else frozenset(latched)
        self._stack = contextlib.ExitStack()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self._seq: dict[str, int] = {}
        self._known: dict[tuple[str, str], int] = {}  # (topic, type name as given) -> id
        self.counts: dict[str, int] = {}

    def __enter__(self) -> LogWriter:
        with contextlib.ExitStack() as stack:
            self._tmp = stack.enter_context(atomic_path(self.path))
            self._file = stack.enter_context(open(self._tmp, "wb"))
            self._stack = stack.pop_all()
        try:
            self._writer = _LeanWriter(
                self._file, chunk_size=self.chunk_size, compression=CompressionType.ZSTD
            )
            self._writer.start(profile="ros2", library=f"fuzzyslam {__version__}")
            # as rosbag2 writes it: the distribution whose message definitions (the
            # typestore's) and QoS format (offered_qos) the file has
            self._writer.add_metadata("rosbag2", {"ROS_DISTRO": self.ros_distro})
        except BaseException:
            if not self._stack.__exit__(*sys.exc_info()):
                raise
        return self

    def _channel(self, topic: str, typename: str) -> int:
        typename = normalise_typename(typename)
        if topic in self._channels:
            cid, known = self._channels[topic]
            if known != typename:
                raise ValueError(f"topic {topic} already has type {known}, not {typename}")
            return cid
        if typename not in self._schemas:
            self._schemas[typename] = self._writer.register_schema(
                name=typename, encoding="ros2msg", data=msgdef(typename, self.ros_distro).encode()
            )
        cid = self._writer.register_channel(
            topic=topic,
            message_encoding="cdr",
            schema_id=self._schemas[typename],
            metadata={"offered_qos_profiles": offered_qos(topic in self.latched)},
        )
        self._channels[topic] = (cid, typename)
        self._seq[topic] = 0
        self.counts[topic] = 0
        return cid

    def write(self, topic: str, typename: str, msg: Any, t: float) -> None:
        """Write a message (a rosbags message, or its CDR bytes as ``streams/cdr_encode.py``
        writes them) with log and publish time ``t`` (seconds of log time; MCAP times
        are unsigned, so a time before the epoch, e.g. a message stamped before a
        simulation's t = 0, is logged at 0: its header keeps its stamp)."""
        data = msg if isinstance(msg, bytes) else serialize(msg, typename, self.ros_distro)
        self.write_cdr(topic, typename, data, t)

    def write_cdr(self, topic: str, typename: str, data: bytes, t: float) -> None:
        """Write an already CDR-serialised message of type ``typename`` (as ``write``)."""
        cid = self._known.get((topic, typename))
        if cid is None:
            cid = self._known[topic, typename] = self._channel(topic, typename)
        ns = max(to_ns(t), 0)
        self._writer.add_message(
            channel_id=cid, log_time=ns, publish_time=ns, data=data, sequence=self._seq[topic]
        )
        self._seq[topic] += 1
        self.counts[topic] += 1

    def write_cdr_at(
        self, topics: list[str], typenames: list[str], datas: list[bytes], t: float
    ) -> None:
        """:meth:`write_cdr` of one already serialised message per topic, all at time ``t``
        (a sonar ring, a robot step's messages), in order: the same file."""
        known = self._known
        ids = [known.get(key) for key in zip(topics, typenames, strict=True)]
        if None in ids:  # a new channel's record goes before its first message
            for args in zip(topics, typenames, datas, strict=True):
                self.write_cdr(*args, t)
            return
        seqs = []
        for topic in topics:
            seqs.append(self._seq[topic])
            self._seq[topic] += 1
            self.counts[topic] += 1
        self._writer.add_messages(ids, max(to_ns(t), 0), datas, seqs)

    def metadata(self, name: str, data: dict[str, str]) -> None:
        """Add an MCAP metadata record (string to string map)."""
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def json_metadata(self, name: str, obj: Any) -> None:
        """Add a metadata record ``name`` holding ``{"json": <obj as JSON>}``."""
        self.metadata(name, {"json": json.dumps(obj, sort_keys=True)})

    def attachment(self, name: str, media_type: str, data: bytes, t: float = 0.0) -> None:
        """Add an attachment (e.g. the world as YAML) at log time ``t``."""
        ns = to_ns(t)
        self._writer.add_attachment(
            log_time=ns, create_time=ns, name=name, media_type=media_type, data=data
        )

    def __exit__(self, exc_type, exc, tb) -> bool:
        """Finish the file, close it, then let atomic_path rename it into place; an
        exception at any step (the block's, or one of ``finish``/``close``) goes to
        atomic_path instead, which removes the temporary file."""
        if exc_type is None:
            try:
                self._writer.finish()
            except BaseException:
                if not self._stack.__exit__(*sys.exc_info()):
                    raise
                return False
        return bool(self._stack.__exit__(exc_type, exc, tb))
