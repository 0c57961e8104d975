"""The log's /tf read in a forked process while ``fuzzyslam run`` starts (issue 16).

A log whose /tf carries odom -> base has its whole odom -> base series read before the
filter starts (``log_setup.tf_frames``: map -> odom is written against it): on the paper
log 15090 messages spread over all of its 100 chunks (100 MB decompressed), 0.2-0.3 s of
decompression and decoding on the critical path, while the second core idles (the
process importing, loading the map). ``fuzzyslam run`` therefore opens the log first
thing and, when its TFMessage topics span at least ``MIN_CHUNK_BYTES`` of chunks, forks a
process (:func:`read_ahead`) that reads every tf2_msgs/TFMessage topic of it
(:func:`read_transforms`: per topic, the messages' log times and, per (parent, child)
frame pair, the first message holding it and every one of its transforms, as
``tf_frames``' loop collects them) and sends that back; ``tf_frames`` takes it
(:func:`take`) instead of reading the topic itself. Below that size the process would
cost more than it saves (its start against a read of a few tens of ms).

The series are the same floats: the payloads of one layout are checked against the first,
which the message decoder reads, and their numbers read with numpy
(``streams.cdr.decode_tf_messages``). Reading can change what the reader reports (its damage
counts: a damaged chunk, an undecodable message, an index that does not match): the
answer is used only if the child's read changed none of it, every payload decoded, and
the file is the one the run opened (size, modification time, inode); else ``tf_frames``
reads the topic itself, as without this process. The child's memory is bounded
(``MAX_PAYLOAD_BYTES``: past it, no answer). The child is reaped once taken, when the log's
inputs are opened (:func:`discard`) and on every path out of :func:`read_ahead`. Where the
run forks no input process (``fuzzyslam.forked.wanted``: one CPU, ``--no-prefetch``),
none is forked here either: ``tf_frames`` reads as before.
"""

from __future__ import annotations

import contextlib
import os
import pickle
from collections.abc import Iterator
from pathlib import Path
from typing import Any

# payload bytes kept at most (the paper log's /tf: 1.5 MB), past which no answer: the
# child's memory stays within a few times this (a transform takes at least 40 bytes)
MAX_PAYLOAD_BYTES = 32 << 20
# chunks (decompressed) holding the TFMessage topics from which a process reads them: the
# paper log's 100 MB take 0.2 s to read, data/sample.mcap's 9 MB 0.02 s, less than the
# process's start
MIN_CHUNK_BYTES = 32 << 20

# path (resolved) -> (pid, the pipe's read end, the file's identity when opened): the
# child forked by read_ahead, not taken
_PENDING: dict[str, tuple[int, Any, tuple[int, int, int]]] = {}


def _key(path: str | os.PathLike) -> str:
    return os.fspath(Path(path).resolve())


def _identity(path: str | os.PathLike) -> tuple[int, int, int]:
    st = os.stat(path)
    return st.st_size, st.st_mtime_ns, st.st_ino


class TopicTransforms:
    """What ``tf_frames``' loop reads of one TFMessage topic: the log times (s) of its
    messages ``msg_t`` and, per frame pair (parent, child; leading slashes stripped),
    ``pairs[pair] = (first, t, logged, xyq)``: the index of the first message holding it,
    its transforms' stamps (s), their messages' log times (s) and (x, y, qx, qy, qz, qw).

    Parameters
    ----------
    msg_t : array_like of float
        The messages' log times (s), in log-time order.
    pairs : dict
        Frame pair -> (first message index, stamps, log times, (N, 6) translations and
        rotations).
    """

    def __init__(self, msg_t, pairs: dict) -> None:
        self.msg_t = msg_t
        self.pairs = pairs


def read_transforms(path: str | os.PathLike, reader=None) -> dict[str, Any] | None:
    """Every tf2_msgs/TFMessage topic of the log, read as ``tf_frames`` reads one
    (module docstring); None if reading changed the reader's damage counts, if the file
    is read by a walk of its records (:meth:`LogReader.payloads`), or past
    ``MAX_PAYLOAD_BYTES`` of payloads.

    Parameters
    ----------
    path : path
        The MCAP log.
    reader : LogReader, optional
        It opened (default: opened here).

    Returns
    -------
    dict or None
        Topic -> :class:`TopicTransforms`; with the file's identity under the key
        ``"identity"`` (size, modification time ns, inode).
    """
    import copy

    import numpy as np

    from fuzzyslam.streams import messages as M
    from fuzzyslam.streams.cdr import decode_tf_messages
    from fuzzyslam.streams.reader import LogReader

    identity = _identity(path)
    if reader is None:
        reader = LogReader(path)
    topics = [tp for tp, ty in reader.topics.items() if ty == M.TF_MESSAGE]
    before = copy.deepcopy(reader.damage_state())
    read = reader.payloads(topics)
    if read is None:
        return None
    times: dict[str, list[float]] = {tp: [] for tp in topics}
    bufs: dict[str, list[bytes]] = {tp: [] for tp in topics}
    kept = 0
    for topic, t, payload in read:
        times[topic].append(t)
        bufs[topic].append(bytes(payload))
        kept += len(payload)
        if kept > MAX_PAYLOAD_BYTES:
            return None
    if reader.damage_state() != before:
        return None
    out: dict[str, Any] = {"identity": identity}
    for tp in topics:
        got = decode_tf_messages(bufs[tp])
        if got is None:
            return None
        msg, names, stamp, xyq = got
        msg_t = np.array(times[tp], dtype=float)
        pairs = {}
        for k, pair in enumerate(names):
            rows = np.flatnonzero(stamp[1] == k)
            pairs[pair] = (int(msg[rows[0]]), stamp[0][rows], msg_t[msg[rows]], xyq[rows])
        out[tp] = TopicTransforms(msg_t, pairs)
    return out


def _child(conn, path: str, reader) -> None:
    """The forked process's work: :func:`read_transforms` sent to the parent (None on
    any exception: the parent then reads the topic itself, and meets it there)."""
    try:
        result = read_transforms(path, reader)
    except Exception:
        result = None
    with contextlib.suppress(OSError):
        conn.send_bytes(pickle.dumps(result, pickle.HIGHEST_PROTOCOL))


@contextlib.contextmanager
def read_ahead(path: str | os.PathLike, wanted: bool = True) -> Iterator[None]:
    """Meanwhile (``wanted``), a forked process reads the log's TFMessage topics
    (:func:`read_transforms`) for :func:`take`; reaped on leaving if not taken before.

    Parameters
    ----------
    path : path
        The MCAP log.
    wanted : bool
        Fork it (``fuzzyslam.forked.wanted``: where the run forks its input process).

    Returns
    -------
    contextmanager
    """
    opened = _worth_reading(path) if wanted else None
    if opened is None:
        yield
        return
    reader, identity = opened
    from fuzzyslam.forked import TO_PARENT, fork_child

    key = None
    with contextlib.suppress(OSError):
        key = _key(path)
        forked = fork_child(lambda ends: _child(ends[0], os.fspath(path), reader), (TO_PARENT,))
        if forked is not None:
            _PENDING[key] = (forked[0], forked[1][0], identity)
    try:
        yield
    finally:
        if key is not None:
            discard(key)


def _worth_reading(path: str | os.PathLike):
    """The log opened and its identity, if its TFMessage topics span at least
    ``MIN_CHUNK_BYTES`` of chunks; else (or if it does not open: the run says why) None."""
    try:
        from fuzzyslam.streams import messages as M
        from fuzzyslam.streams.reader import LogReader

        identity = _identity(path)
        reader = LogReader(path)
        topics = [tp for tp, ty in reader.topics.items() if ty == M.TF_MESSAGE]
        size = reader.chunk_bytes(topics) if topics else None
    except Exception:
        return None
    return (reader, identity) if size is not None and size >= MIN_CHUNK_BYTES else None


def discard(path: str | os.PathLike) -> None:
    """Reap the process reading ``path`` ahead, if any (its answer unused).

    Parameters
    ----------
    path : path
        The log.
    """
    with contextlib.suppress(OSError):
        pending = _PENDING.pop(_key(path), None)
        if pending is not None:
            from fuzzyslam.forked import reap

            pid, conn, _ = pending
            conn.close()
            reap(pid)


def take(path: str | os.PathLike, topic: str) -> TopicTransforms | None:
    """The transforms of ``topic`` read ahead for the log ``path`` (waiting for them), or
    None: no process read it, it failed or gave no answer (module docstring), or the
    file is no longer the one it read. The process is reaped.

    Parameters
    ----------
    path : path
        The log.
    topic : str
        The TFMessage topic.

    Returns
    -------
    TopicTransforms or None
    """
    try:
        pending = _PENDING.pop(_key(path), None)
    except OSError:
        return None
    if pending is None:
        return None
    from fuzzyslam.forked import reap

    pid, conn, identity = pending
    try:
        result = pickle.loads(conn.recv_bytes())
    except (EOFError, OSError, pickle.UnpicklingError):
        result = None
    finally:
        conn.close()
        reap(pid)
    try:
        if result is None or not result["identity"] == identity == _identity(path):
            return None
    except OSError:
        return None
    return result.get(topic)
