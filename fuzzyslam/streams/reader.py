"""MCAP log reader: ROS 2 messages of a recording, fast, and tolerant of damage.

The one way fuzzyslam reads MCAP (nothing outside ``streams/`` touches its records).
An intact file is read through its summary and indexes (``streams/indexed.py``): only
the chunks holding the wanted topics are decompressed, only the wanted messages read,
in log-time order. A file whose summary is missing or damaged (a robot that lost power
mid-recording) is read record by record (``streams/recover.py``), in file order, as far
as it is intact; a chunk or index that does not match the file met mid-way hands over
to that walk, from the last good chunk on, without a message given twice. Payloads are
decoded by ``streams/cdr.py`` (the frequent types) or rosbags (the rest).

``damage()`` says how much was lost (``truncated``, ``lost_bytes``, ``salvaged_messages``,
``damaged_records``, ``undecodable``). A file that is not MCAP is one clear InputError.
"""

from __future__ import annotations

import contextlib
import copy
import json
import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from mcap.records import Attachment, Channel, Message, Metadata, Schema

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import check_input_file
from fuzzyslam.stamps import to_ns
from fuzzyslam.streams.cdr import DECODERS, decoder
from fuzzyslam.streams.indexed import (
    IndexMismatch,
    Summary,
    chunk_offsets,
    indexed_messages,
    read_summary,
    schema_text,
)
from fuzzyslam.streams.recover import MCAP_MAGIC, Damage, walk
from fuzzyslam.streams.typestore import file_deserializer, normalise_typename, typestore

__all__ = ["MCAP_MAGIC", "LogMessage", "LogReader"]


class LogMessage(NamedTuple):
    """One decoded message: topic, log time (s, and exact ns), ROS type name, message.

    (Immutable; a named tuple, which costs a third of a frozen dataclass to make.)"""

    topic: str
    t: float
    typename: str
    msg: Any
    t_ns: int


def _last_stamp(
    batch: list, last_ns: int, seen: set[tuple[int, int]]
) -> tuple[int, set[tuple[int, int]]]:
    """After a batch of (log time, channel id, sequence, payload) in time order: the last
    log time given and the (channel id, sequence) given at it, ``seen`` of the batches
    before included when they end at that time too (a walk resuming after an index
    mismatch starts there and leaves them out). Once per batch, not per message."""
    if not batch:
        return last_ns, seen
    t_last = batch[-1][0]
    at = set()
    for t, cid, seq, _ in reversed(batch):
        if t != t_last:
            break
        at.add((cid, seq))
    else:  # the whole batch at t_last: the run may go on from the batches before
        if t_last == last_ns:
            at |= seen
    return t_last, at


def bag_file(path: str | os.PathLike) -> Path:
    """The MCAP file of a log given as a file, or as the folder ``ros2 bag record -s
    mcap`` writes (``metadata.yaml`` and ``NAME_0.mcap``) when it holds one.

    Parameters
    ----------
    path : path
        A file, or a folder.

    Returns
    -------
    Path
        ``path`` itself when it is not a folder.

    Raises
    ------
    InputError
        A folder with no ``.mcap`` file, or with several (a bag split by size or
        duration: one line saying how to merge them), or a run's output folder.
    """
    p = Path(path)
    if not p.is_dir():
        return p
    if (p / "estimates.mcap").exists() or (p / "trajectory.tum").exists():
        raise InputError(p, "log is a run's output folder (its estimates), not a log")
    files = sorted(p.glob("*.mcap"))
    if len(files) == 1:
        return files[0]
    if not files:
        raise InputError(p, "log is a folder with no .mcap file (a bag recorded as MCAP?)")
    raise InputError(
        p,
        f"log is a bag split into {len(files)} files ({files[0].name} ... "
        f"{files[-1].name}): merge them into one first (mcap merge {p}/*.mcap -o "
        "merged.mcap) and pass that",
    )


@dataclass(frozen=True)
class _Scan:
    """What the record walk of a file without a summary found (read only)."""

    topics: dict[str, str]
    counts: dict[str, int]
    metadata: dict[str, dict[str, str]]
    attachments: dict[str, bytes]
    span_ns: tuple[int, int]
    damage: Damage


# The record walks of files without a usable summary in the current command
# (:func:`shared_walks`; None outside one), by the file's identity (device, inode, size,
# modification time): a command opens its log several times (the config preset's choice,
# the stage's set-up, its inputs), and a walk costs about 0.7 s per 40 MB. A file that
# changed is walked again; the last few are kept.
_SCANS: dict[tuple[int, int, int, int], _Scan] | None = None
SCANS_KEPT = 4


@contextlib.contextmanager
def shared_walks() -> Iterator[None]:
    """One command: in the block, the record walk of a log without a summary serves
    every reader of the same unchanged file (``LogReader``); forgotten at the end.
    Only within a command: a file rewritten in place with the same size within the
    file system's clock tick (a few ms) would keep its identity.

    Yields
    ------
    None
    """
    global _SCANS
    before, _SCANS = _SCANS, {} if _SCANS is None else _SCANS
    try:
        yield
    finally:
        _SCANS = before


def lost_something(report: dict[str, Any] | None) -> bool:
    """Whether a damage report (:meth:`LogReader.damage`, a summary's ``log_damage``) says
    the log lost anything: its summary or footer, bytes, or records.

    Parameters
    ----------
    report : dict or None
        The report (None: no report).

    Returns
    -------
    bool
    """
    return bool(
        report
        and (report.get("truncated") or report.get("lost_bytes") or report.get("damaged_records"))
    )


class LogReader:
    """Read a ROS 2 MCAP recording (a file, or a ros2 bag folder holding one:
    :func:`bag_file`).

    Attributes after opening: ``path``, ``size`` (bytes), ``topics`` (topic -> type
    name), ``counts`` (topic -> message count), ``start``/``end`` (log times of the
    first and last message, s), ``metadata`` (name -> dict), ``attachments`` (name ->
    bytes). ``messages`` gives the decoded messages, ``damage`` what was lost.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = check_input_file(bag_file(path), "log")
        self.size = self.path.stat().st_size
        with open(self.path, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
            if head != MCAP_MAGIC:
                raise InputError(self.path, "not an MCAP file (bad magic bytes)")
            self._summary: Summary | None = read_summary(f, self.size)
        self.topics: dict[str, str] = {}
        self.counts: dict[str, int] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.attachments: dict[str, bytes] = {}
        self.start = 0.0
        self.end = 0.0
        self._damage = Damage()
        self._decoders: dict[tuple[str, str | None], Callable[[Any], Any] | None] = {}
        # channel id -> the log's own ros2msg definition of its type (its Schema record)
        self._texts: dict[int, str] = {}
        # decompressed chunks shared by this reader's walks (indexed.indexed_messages),
        # forgotten when the file changes (its size or modification time)
        self._recent: dict[int, bytes] = {}
        self._recent_of: tuple[int, int] | None = None
        s = self._summary
        if s is None:
            self._scan_stream()
            return
        for topic, schema in s.channels.values():
            self.topics[topic] = normalise_typename(schema)
        self._texts = dict(s.definitions)
        self.counts = dict(s.counts)
        self._span_ns = (int(s.start), int(s.end))
        self.start, self.end = s.start / 1e9, s.end / 1e9
        self.metadata, self.attachments = s.metadata, s.attachments

    def _scan_stream(self) -> None:
        """Topics, counts, times, metadata and attachments of a file without a usable
        summary, from a walk over its records (which counts the damage), or from this
        command's earlier walk of the same file (:func:`shared_walks`)."""
        st = self.path.stat()
        key = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
        kept = _SCANS if _SCANS is not None else {}
        scan = kept.get(key)
        if scan is None:
            scan = kept[key] = self._walk_stream()
            while len(kept) > SCANS_KEPT:
                del kept[next(iter(kept))]  # the oldest walk
        self.topics, self.counts = dict(scan.topics), dict(scan.counts)
        self.metadata, self.attachments = dict(scan.metadata), dict(scan.attachments)
        self._span_ns = scan.span_ns
        self.start, self.end = scan.span_ns[0] / 1e9, scan.span_ns[1] / 1e9
        self._damage = copy.deepcopy(scan.damage)  # this reader's own count from here on

    def _walk_stream(self) -> _Scan:
        """:meth:`_scan_stream`'s walk over the records."""
        topics: dict[str, str] = {}
        counts: dict[str, int] = {}
        metadata: dict[str, dict[str, str]] = {}
        attachments: dict[str, bytes] = {}
        schemas: dict[int, str] = {}
        t0, t1, n = None, None, 0
        channels: dict[int, str] = {}
        dmg = Damage()
        with open(self.path, "rb") as f:
            for rec in walk(f, self.size, dmg):
                if isinstance(rec, Schema):
                    schemas[rec.id] = normalise_typename(rec.name)
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec.topic
                    if rec.schema_id in schemas:
                        topics[rec.topic] = schemas[rec.schema_id]
                elif isinstance(rec, Message):
                    topic = channels.get(rec.channel_id)
                    if topic is not None:
                        counts[topic] = counts.get(topic, 0) + 1
                    t0 = rec.log_time if t0 is None else min(t0, rec.log_time)
                    t1 = rec.log_time if t1 is None else max(t1, rec.log_time)
                    n += 1
                elif isinstance(rec, Metadata):
                    metadata[rec.name] = dict(rec.metadata)
                elif isinstance(rec, Attachment):
                    attachments[rec.name] = bytes(rec.data)
        dmg.truncated = True  # no usable summary: the file is damaged even if all parsed
        if n == 0 and not topics:
            raise InputError(self.path, "MCAP file holds no readable messages (damaged or empty)")
        return _Scan(topics, counts, metadata, attachments, (int(t0 or 0), int(t1 or 0)), dmg)

    # -- queries ------------------------------------------------------------------

    def damage(self) -> dict[str, Any]:
        """How much of the file was lost (so far), for a stage's JSON summary.

        ``truncated``: the summary/footer is missing or damaged (the file was read by a
        record walk); ``lost_bytes``: bytes past the last whole record (a cut-off tail,
        partly salvaged) and of damaged records; ``salvaged_messages``: messages recovered
        from a cut-off chunk; ``damaged_records``: records (chunks, indexes, broken
        framing) that failed to parse or did not match the file, skipped;
        ``undecodable``: messages skipped because their payload failed to decode.
        """
        d = self._damage
        return {
            "truncated": bool(d.truncated),
            "lost_bytes": int(d.lost_bytes),
            "lost_fraction": round(d.lost_bytes / self.size, 6) if self.size else 0.0,
            "salvaged_messages": int(d.salvaged_messages),
            "damaged_records": int(d.damaged_records),
            "undecodable": int(d.undecodable),
        }

    def damage_state(self) -> Damage:
        """The damage counted so far, whole (``damage()``'s source): what a child process
        that read the messages (``slam/prefetch.py``) sends back to :meth:`restore_damage`."""
        return self._damage

    def restore_damage(self, damage: Damage) -> None:
        """Take the damage counted by another reader of the same file (``damage_state``)."""
        self._damage = damage

    def fingerprint(self) -> str:
        """What tells this recording from another, whatever the file is called: the
        log times (ns) of its first and last message and its topics with their message
        counts (from the summary, or the record walk of a file without one), as a
        canonical JSON text. A copy of the file has the same; another recording of the
        same place does not.

        Returns
        -------
        str
        """
        return json.dumps(
            {"span_ns": list(self._span_ns), "counts": dict(sorted(self.counts.items()))},
            sort_keys=True,
            separators=(",", ":"),
        )

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

    def last_time(self, topic: str) -> float | None:
        """The log time of the last message of ``topic`` (a stream that stopped before the
        log ended). On an intact file only its last chunks are read: a chunk whose
        Message Indexes name the topic holds one of its messages at or after the chunk's
        start, so the last one lies at or after the latest such start; else (no summary,
        chunks without Message Indexes) all its messages are read.

        Parameters
        ----------
        topic : str
            The topic.

        Returns
        -------
        float or None
            Seconds; None when the topic has no message.
        """
        s, start = self._summary, None
        if s is not None and s.chunks and all(c.message_indexes for c in s.chunks):
            ids = {cid for cid, (tp, _) in s.channels.items() if tp == topic}
            starts = [c.start for c in s.chunks if ids & c.message_indexes.keys()]
            if not starts:
                return None
            start = max(starts) / 1e9 - 1e-3  # (a ms earlier: the float's rounding)
        last = None
        for m in self.messages([topic], start):
            last = m.t
        return last

    def messages(
        self, topics: Iterable[str] | None = None, start: float | None = None
    ) -> Iterator[LogMessage]:
        """Decoded messages of ``topics`` (all if None) in log-time order.

        ``start`` (s): leave out the messages logged before it (on an intact file, the
        chunks that end before it are not even read). On a file without a usable summary,
        messages come in file order, as far as the file is intact. Messages that fail to
        decode are skipped and counted in ``undecodable``.
        """
        wanted = set(topics) if topics is not None else None
        start_ns = -1 if start is None else to_ns(start)
        s = self._summary
        if s is None:
            # the damage was counted when opening: this walk's counts are dropped
            yield from self._walk_messages(wanted, start_ns, Damage(), {})
            return
        chans = {
            cid: (topic, normalise_typename(schema))
            for cid, (topic, schema) in s.channels.items()
            if wanted is None or topic in wanted
        }
        if not s.chunks:  # messages outside chunks (a file written without chunking)
            sync = chunk_offsets(s)
            yield from self._walk_messages(
                wanted, start_ns, self._damage, chans, data_end=s.data_end, sync=sync
            )
            return
        fns = {
            cid: (topic, typename, self._decoder(typename, self._texts.get(cid)))
            for cid, (topic, typename) in chans.items()
        }
        last_ns, seen = -1, set()
        dmg = self._damage
        with open(self.path, "rb") as f:
            st = os.fstat(f.fileno())
            if (st.st_size, st.st_mtime_ns) != self._recent_of:
                self._recent, self._recent_of = {}, (st.st_size, st.st_mtime_ns)
            try:
                for batch in indexed_messages(f, s, set(chans), start_ns, dmg, self._recent):
                    for t_ns, cid, _seq, payload in batch:
                        topic, typename, fn = fns[cid]
                        if fn is None:
                            dmg.undecodable += 1
                            continue
                        try:
                            msg = fn(payload)
                        except Exception:  # truncated or inconsistent payload
                            dmg.undecodable += 1
                            continue
                        yield LogMessage(topic, t_ns / 1e9, typename, msg, t_ns)
                    last_ns, seen = _last_stamp(batch, last_ns, seen)
                return
            except IndexMismatch as exc:
                mismatch = exc
        try:  # walk on from the last good chunk (the messages already given left out)
            yield from self._walk_messages(
                wanted,
                max(start_ns, last_ns),
                self._damage,
                chans,
                seen,
                mismatch.resume,
                s.data_end,
                chunk_offsets(s),
            )
        finally:  # the mismatch is one damaged record, unless the walk counted it
            self._damage.record(mismatch.offset, 0)

    def chunk_bytes(self, topics: Iterable[str]) -> int | None:
        """The decompressed bytes of the chunks that hold messages of ``topics`` (what
        reading them through the index decompresses); None for a file read by a walk of
        its records (no summary, or chunks without one).

        Parameters
        ----------
        topics : iterable of str
            The topics.

        Returns
        -------
        int or None
        """
        chans = self._indexed_channels(topics)
        if chans is None:
            return None
        return sum(
            c.size
            for c in self._summary.chunks
            if not c.message_indexes or chans.keys() & c.message_indexes.keys()
        )

    def payloads(self, topics: Iterable[str]) -> Iterator[tuple[str, float, Any]] | None:
        """The undecoded messages of ``topics`` as :meth:`messages` reads them through the
        file's index: (topic, log time s, CDR payload), in log-time order; None for a file
        read by a walk of its records (no summary, or chunks without one). Damaged chunks
        are counted and skipped as :meth:`messages` does; a chunk that does not match the
        index raises ``IndexMismatch`` (:meth:`messages` walks on from there instead).

        Parameters
        ----------
        topics : iterable of str
            The topics.

        Returns
        -------
        iterator of (str, float, memoryview) or None
        """
        chans = self._indexed_channels(topics)
        return None if chans is None else self._payloads(self._summary, chans)

    def _indexed_channels(self, topics: Iterable[str]) -> dict[int, str] | None:
        """Channel id -> topic of the channels of ``topics``, for a file read through its
        index; None for one read by a walk of its records (no summary, or no chunks)."""
        s = self._summary
        if s is None or not s.chunks:
            return None
        wanted = set(topics)
        return {cid: topic for cid, (topic, _schema) in s.channels.items() if topic in wanted}

    def _payloads(self, s: Summary, chans: dict[int, str]) -> Iterator[tuple[str, float, Any]]:
        with open(self.path, "rb") as f:
            for batch in indexed_messages(f, s, set(chans), -1, self._damage, {}):
                for t_ns, cid, _seq, payload in batch:
                    yield chans[cid], t_ns / 1e9, payload

    def _walk_messages(
        self,
        wanted: set[str] | None,
        from_ns: int,
        dmg: Damage,
        channels: dict[int, tuple[str, str]],
        seen: set[tuple[int, int]] | frozenset = frozenset(),
        start: int = len(MCAP_MAGIC),
        data_end: int | None = None,
        sync: list[int] | None = None,
    ) -> Iterator[LogMessage]:
        """Messages of the record walk from file offset ``start`` in file order; those
        logged before ``from_ns`` and the ``seen`` (channel id, sequence) at ``from_ns``
        left out. ``channels``: channel id -> (topic, type name) known beforehand."""
        schemas: dict[int, str] = {}
        texts: dict[int, str | None] = {}  # schema id -> its definition text
        channels = dict(channels)
        chan_texts = {cid: self._texts.get(cid) for cid in channels}
        with open(self.path, "rb") as f:
            for rec in walk(f, self.size, dmg, start, data_end, sync):
                if isinstance(rec, Schema):
                    schemas[rec.id] = normalise_typename(rec.name)
                    texts[rec.id] = schema_text(rec.encoding, rec.data)
                elif isinstance(rec, Channel):
                    if rec.schema_id in schemas and rec.id not in channels:
                        channels[rec.id] = (rec.topic, schemas[rec.schema_id])
                        chan_texts[rec.id] = texts.get(rec.schema_id)
                elif isinstance(rec, Message):
                    if rec.log_time < from_ns or (
                        rec.log_time == from_ns and (rec.channel_id, rec.sequence) in seen
                    ):
                        continue
                    ch = channels.get(rec.channel_id)
                    if ch is None or (wanted is not None and ch[0] not in wanted):
                        continue
                    text = chan_texts.get(rec.channel_id)
                    out = self._decode(ch[0], ch[1], rec.log_time, rec.data, text)
                    if out is not None:
                        yield out

    def _decoder(self, typename: str, text: str | None = None) -> Callable[[Any], Any] | None:
        """The payload decoder of a type as its channel's schema defines it (``text``;
        None: a type neither the log's definition nor the typestore knows): the fast
        decoders, else rosbags by that definition (a message that changed between ROS 2
        releases is read as the log recorded it, channel by channel), else by the
        typestore's."""
        key = (typename, text)
        if key not in self._decoders:
            if text is not None:  # made when first needed (no rosbags import before)
                self._decoders[key] = decoder(typename, file_deserializer(typename, text))
            elif typename in DECODERS or typename in typestore().types:
                self._decoders[key] = decoder(typename)
            else:
                self._decoders[key] = None
        return self._decoders[key]

    def _decode(
        self, topic: str, typename: str, t_ns: int, payload: Any, text: str | None = None
    ) -> LogMessage | None:
        fn = self._decoder(typename, text)
        if fn is None:
            self._damage.undecodable += 1
            return None
        try:
            msg = fn(payload)
        except Exception:  # truncated or inconsistent payload (CdrError, rosbags' errors)
            self._damage.undecodable += 1
            return None
        return LogMessage(topic, t_ns / 1e9, typename, msg, t_ns)
