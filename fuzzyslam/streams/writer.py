"""MCAP log writer: ROS 2 profile, ros2msg schemas, CDR messages, zstd chunks.

Writes to a temporary name and renames onto the target only when the file is finished,
closed and flushed to the disk without error (fileio.atomic_path), so a failed or
interrupted command -- also a disk that fills up, or Ctrl-C inside ``finish`` -- leaves
the previous file, if any, as it was.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path
from typing import Any

from mcap.writer import CompressionType, Writer

from fuzzyslam import __version__
from fuzzyslam.fileio import atomic_path
from fuzzyslam.streams.typestore import msgdef, normalise_typename, serialize


def sec_to_ns(t: float) -> int:
    """Seconds (float) to integer nanoseconds, rounded."""
    return round(t * 1e9)


class LogWriter:
    """Write ROS 2 messages to one MCAP file.

    >>> with LogWriter("out.mcap") as w:          # doctest: +SKIP
    ...     w.write("/sonar/s00", "sensor_msgs/msg/Range", msg, t)
    """

    def __init__(self, path: str | os.PathLike, chunk_size: int = 1024 * 1024) -> None:
        self.path = Path(path)
        self.chunk_size = chunk_size
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
            self._writer = Writer(
                self._file, chunk_size=self.chunk_size, compression=CompressionType.ZSTD
            )
            self._writer.start(profile="ros2", library=f"fuzzyslam {__version__}")
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
                name=typename, encoding="ros2msg", data=msgdef(typename).encode()
            )
        cid = self._writer.register_channel(
            topic=topic, message_encoding="cdr", schema_id=self._schemas[typename]
        )
        self._channels[topic] = (cid, typename)
        self._seq[topic] = 0
        self.counts[topic] = 0
        return cid

    def write(self, topic: str, typename: str, msg: Any, t: float) -> None:
        """Write a message with log and publish time ``t`` (seconds of log time)."""
        self.write_cdr(topic, typename, serialize(msg, typename), t)

    def write_cdr(self, topic: str, typename: str, data: bytes, t: float) -> None:
        """Write an already CDR-serialised message of type ``typename`` (as ``write``)."""
        cid = self._known.get((topic, typename))
        if cid is None:
            cid = self._known[topic, typename] = self._channel(topic, typename)
        ns = sec_to_ns(t)
        self._writer.add_message(
            channel_id=cid, log_time=ns, publish_time=ns, data=data, sequence=self._seq[topic]
        )
        self._seq[topic] += 1
        self.counts[topic] += 1

    def metadata(self, name: str, data: dict[str, str]) -> None:
        """Add an MCAP metadata record (string to string map)."""
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def json_metadata(self, name: str, obj: Any) -> None:
        """Add a metadata record ``name`` holding ``{"json": <obj as JSON>}``."""
        self.metadata(name, {"json": json.dumps(obj, sort_keys=True)})

    def attachment(self, name: str, media_type: str, data: bytes, t: float = 0.0) -> None:
        """Add an attachment (e.g. the world as YAML) at log time ``t``."""
        ns = sec_to_ns(t)
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
