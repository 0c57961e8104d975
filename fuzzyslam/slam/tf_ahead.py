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
(:func:`decode_transforms`). Reading can change what the reader reports (its damage
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
        got = decode_transforms(bufs[tp])
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


def decode_transforms(bufs: list[bytes]):
    """The transforms of little-endian CDR tf2_msgs/TFMessage payloads, as
    ``streams.cdr.decode_tf_message`` reads them and ``tf_frames`` takes them, at once
    for the payloads of one layout (the same length, transform count, frame names; a
    constant-rate /tf has one): each payload of a layout is checked against the first,
    which that decoder reads; their stamps and floats are read with numpy, the same
    bits. None if a payload is not little-endian or does not decode (``tf_frames``
    would count it undecodable), or past 64 layouts.

    Parameters
    ----------
    bufs : list of bytes
        The payloads, in log-time order.

    Returns
    -------
    (msg, names, (stamps, pair), xyq) or None
        Per transform, in order (message, then transform): its message's index (T,),
        the frame pairs (parent, child; slashes stripped) in order of first sight, the
        stamp sec + nanosec 1e-9 (T,) and the index of its pair in ``names`` (T,), and
        (x, y, qx, qy, qz, qw) (T, 6).
    """
    import numpy as np

    from fuzzyslam.streams.cdr import decode_tf_message

    left = np.arange(len(bufs))
    lengths = np.fromiter((len(b) for b in bufs), dtype=np.int64, count=len(bufs))
    parts = []  # (message indices, transform index, pair, sec, nsec, values (n, 7))
    names: dict[tuple[str, str], int] = {}
    for _ in range(64):
        if not len(left):
            break
        first = bufs[left[0]]
        if first[:2] != b"\x00\x01":
            return None
        try:
            msg = decode_tf_message(first)
        except Exception:
            return None
        same = left[lengths[left] == len(first)]
        rows = np.frombuffer(b"".join(bufs[i] for i in same), np.uint8).reshape(len(same), -1)
        keep = np.all(rows[:, :8] == rows[0, :8], axis=1)  # encapsulation, count
        a = 8
        fields = []
        for ts in msg.transforms:  # decode_tf_message's offsets, its strings compared
            a += (4 - a) % 4
            stamp = a
            a += 8  # sec, nanosec
            for name in (ts.header.frame_id, ts.child_frame_id):
                a += (4 - a) % 4
                end = a + 4 + len(name.encode()) + 1
                keep &= np.all(rows[:, a:end] == rows[0, a:end], axis=1)
                a = end
            a += (4 - a) % 8
            fields.append((stamp, a, ts))
            a += 56
        same, rows = same[keep], rows[keep]
        for j, (stamp, at, ts) in enumerate(fields):
            pair = (str(ts.header.frame_id).lstrip("/"), str(ts.child_frame_id).lstrip("/"))
            sec = np.ascontiguousarray(rows[:, stamp : stamp + 4]).view("<i4").ravel()
            nsec = np.ascontiguousarray(rows[:, stamp + 4 : stamp + 8]).view("<u4").ravel()
            v = np.ascontiguousarray(rows[:, at : at + 56]).view("<f8")
            parts.append((same, j, names.setdefault(pair, len(names)), sec, nsec, v))
        left = np.setdiff1d(left, same, assume_unique=True)
    else:
        if len(left):
            return None
    if not parts:
        return np.zeros(0, int), [], (np.zeros(0), np.zeros(0, int)), np.zeros((0, 6))
    msg = np.concatenate([p[0] for p in parts])
    slot = np.concatenate([np.full(len(p[0]), p[1]) for p in parts])
    order = np.lexsort((slot, msg))  # message order, then the transforms' order
    pair = np.concatenate([np.full(len(p[0]), p[2]) for p in parts])[order]
    sec = np.concatenate([p[3] for p in parts])[order].astype(float)
    nsec = np.concatenate([p[4] for p in parts])[order].astype(float)
    v = np.concatenate([p[5] for p in parts])[order]
    stamps = sec + nsec * 1e-9  # messages.stamp_to_sec
    return msg[order], list(names), (stamps, pair), v[:, [0, 1, 3, 4, 5, 6]]


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
