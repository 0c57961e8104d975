"""The log's /tf read ahead in a forked process (slam/tf_ahead.py, issue 16): what
``tf_frames`` takes from it is what it reads itself, float for float, for every frame
pair and both search rules; payloads of several layouts; no answer where the reader's
counts would change or the file changed."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from fuzzyslam.config import load_config
from fuzzyslam.slam import log_setup, tf_ahead
from fuzzyslam.slam.log_setup import _pair_transforms, _read_pair, tf_frames
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.cdr import decode_tf_messages
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.writer import LogWriter

SAMPLE = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"


def _same(a, b) -> None:
    """Two answers of ``_read_pair`` / ``_pair_transforms``: the same, bit for bit."""
    assert a[0] == b[0]
    for x, y in zip(a[1:], b[1:], strict=True):
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        assert x.shape == y.shape or (x.size == 0 and y.size == 0)
        assert x.tobytes() == y.tobytes()


def _mixed_log(path: Path, late: float = 1.0) -> None:
    """A /tf of several layouts: one and two transforms a message, other frame names,
    leading slashes, an empty message, a pair first seen at ``late`` s."""
    with LogWriter(path) as w:
        for k in range(60):
            t = 0.1 * k
            tfs = [M.transform_stamped(t + 1e-4, "odom", "base_link", 0.01 * k, -0.02 * k,
                                       0.0, 0.003 * k)]  # fmt: skip
            if k % 3 == 0:
                tfs.append(M.transform_stamped(t, "/base_link", "/laser", 0.2, 0.0, 0.1, 0.5))
            if k % 7 == 0:
                tfs = []
            if t >= late:
                tfs.append(M.transform_stamped(t, "map", "odom_long_name", 1.0, 2.0, 0.0, -k))
            w.write("/tf", M.TF_MESSAGE, M.tf_message(tfs), t)


def test_sample_log_pairs_match() -> None:
    """The committed sample log: every pair of /tf and /tf_static, searched or not."""
    got = tf_ahead.read_transforms(SAMPLE)
    assert got is not None
    reader = LogReader(SAMPLE)
    for topic in ("/tf", "/tf_static"):
        ahead = got[topic]
        assert ahead.pairs
        for pair in [*ahead.pairs, ("no", "such")]:
            for search in (True, False):
                _same(
                    _read_pair(reader, topic, pair, True, search),
                    _pair_transforms(ahead, pair, search),
                )


def test_layouts_and_late_pairs(tmp_path: Path, monkeypatch) -> None:
    """Mixed layouts decode as the message decoder reads them; a pair first seen after
    the search window is not found when searched, found otherwise."""
    log = tmp_path / "mixed.mcap"
    _mixed_log(log, late=2.0)
    monkeypatch.setattr(log_setup, "TF_SEARCH_S", 1.0)
    got = tf_ahead.read_transforms(log)
    assert got is not None
    ahead = got["/tf"]
    assert set(ahead.pairs) == {("odom", "base_link"), ("base_link", "laser"),
                                ("map", "odom_long_name")}  # fmt: skip
    reader = LogReader(log)
    for pair in ahead.pairs:
        for search in (True, False):
            _same(
                _read_pair(reader, "/tf", pair, True, search),
                _pair_transforms(ahead, pair, search),
            )
    assert not _pair_transforms(ahead, ("map", "odom_long_name"), True)[0]
    assert _pair_transforms(ahead, ("map", "odom_long_name"), False)[0]


def test_not_little_endian_gives_no_answer() -> None:
    """A payload that is not little-endian CDR: no answer (tf_frames reads it itself)."""
    assert decode_tf_messages([b"\x00\x00\x00\x00\x00\x00\x00\x00"]) is None
    assert decode_tf_messages([b"\x00\x01\x00\x00\xff\xff\xff\xff"]) is None
    msg, names, (stamps, pair), xyq = decode_tf_messages([])
    assert not len(stamps) and not len(pair)
    assert not len(msg) and not names and xyq.shape == (0, 6)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs fork")
def test_read_ahead_taken_once(tmp_path: Path, monkeypatch) -> None:
    """Forked (for any size here), taken once (then None); tf_frames' answer the same as
    its own read; a file changed since: no answer; below ``MIN_CHUNK_BYTES``, none forked."""
    monkeypatch.setattr(tf_ahead, "MIN_CHUNK_BYTES", 0)
    cfg = load_config("paper")
    reader = LogReader(SAMPLE)
    own = tf_frames(reader, cfg, None)
    with tf_ahead.read_ahead(SAMPLE):
        taken = tf_frames(reader, cfg, None)
        assert tf_ahead.take(SAMPLE, "/tf") is None  # taken above
    assert own.odom_to_base == taken.odom_to_base
    assert (own.log_odom is None) == (taken.log_odom is None)
    if own.log_odom is not None:
        for a, b in zip(own.log_odom, taken.log_odom, strict=True):
            assert a.tobytes() == b.tobytes()

    log = tmp_path / "mixed.mcap"
    _mixed_log(log)
    with tf_ahead.read_ahead(log):
        with open(log, "ab") as f:  # the file is no longer the one read ahead
            f.write(b"\0")
        assert tf_ahead.take(log, "/tf") is None
    with tf_ahead.read_ahead(log, wanted=False):
        assert tf_ahead.take(log, "/tf") is None
    with tf_ahead.read_ahead(log):
        tf_ahead.discard(log)
        assert tf_ahead.take(log, "/tf") is None
    monkeypatch.setattr(tf_ahead, "MIN_CHUNK_BYTES", os.path.getsize(SAMPLE) * 100)
    with tf_ahead.read_ahead(SAMPLE):
        assert not tf_ahead._PENDING


def test_payload_bound_gives_no_answer(tmp_path: Path, monkeypatch) -> None:
    """Past ``MAX_PAYLOAD_BYTES`` of payloads: no answer (the child's memory bounded)."""
    log = tmp_path / "mixed.mcap"
    _mixed_log(log)
    assert tf_ahead.read_transforms(log) is not None
    monkeypatch.setattr(tf_ahead, "MAX_PAYLOAD_BYTES", 1000)
    assert tf_ahead.read_transforms(log) is None
