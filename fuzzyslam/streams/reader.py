"""MCAP log reader: ROS 2 messages decoded with rosbags, tolerant of truncated files.

A complete file is read through its summary and index, in log-time order. A file
whose summary is missing or damaged (a robot that lost power mid-recording) is
read record by record as far as it is intact; ``truncated`` and ``lost_bytes``
say how much was lost. A file that is not MCAP is one clear InputError.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Attachment, Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import check_input_file
from fuzzyslam.streams.typestore import deserialize, normalise_typename, typestore

MCAP_MAGIC = b"\x89MCAP0\r\n"


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
    (name -> dict), ``attachments`` (name -> bytes), ``truncated``, ``lost_bytes``.
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

    def _records(self) -> Iterator[Any]:
        """Records of the file in file order, stopping quietly where it is damaged."""
        with open(self.path, "rb") as f:
            reader = StreamReader(f, skip_magic=False)
            it = reader.records
            good = 0
            while True:
                try:
                    rec = next(it)
                except StopIteration:
                    return
                except Exception:
                    self.truncated = True
                    self.lost_bytes = max(self.size - good, 0)
                    return
                good = f.tell()
                yield rec

    def _scan_stream(self) -> None:
        schemas: dict[int, str] = {}
        t0, t1, n = None, None, 0
        counts: dict[str, int] = {}
        channels: dict[int, str] = {}
        for rec in self._records():
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
        if not self.truncated:
            # no usable summary but the records parsed to the end: call it damaged index
            self.truncated = True
        self.counts = counts
        self.start = (t0 or 0) / 1e9
        self.end = (t1 or 0) / 1e9
        if n == 0 and not self.topics:
            raise InputError(self.path, "MCAP file holds no readable messages (damaged or empty)")

    # -- queries ------------------------------------------------------------------

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
        Messages that fail to decode are skipped and counted in ``undecodable``.
        """
        wanted = set(topics) if topics is not None else None
        if self._summary_ok:
            with open(self.path, "rb") as f:
                reader = SeekingReader(f)
                try:
                    for schema, channel, message in reader.iter_messages(
                        topics=sorted(wanted) if wanted is not None else None, log_time_order=True
                    ):
                        if schema is None:
                            continue
                        out = self._decode(channel.topic, schema.name, message)
                        if out is not None:
                            yield out
                except McapError as exc:
                    raise InputError(self.path, f"damaged MCAP data: {exc}") from None
            return
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        for rec in self._records():
            if isinstance(rec, Schema):
                schemas[rec.id] = rec.name
            elif isinstance(rec, Channel):
                if rec.schema_id in schemas:
                    channels[rec.id] = (rec.topic, schemas[rec.schema_id])
            elif isinstance(rec, Message):
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
