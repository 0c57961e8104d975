"""A /odom that stops while /tf's odom -> base_link goes on (slam/log_setup.py
``odom_cut_short``): the odometry is read from /tf, for the whole run, said in one line.

The simulated logs carry each dead-reckoned pose on /odom and as odom -> base_link on
/tf with the same stamp (tests/test_odometry_from_tf.py checks it), so a run whose /odom
stops 20 s into the log must give, to 1e-9, the trajectory of the same log read from
its whole /odom; the old choice read /odom whatever its coverage and held the estimate
still from 20 s on ("fell silent"). ``LogReader.last_time`` (the cheap end of a topic)
is checked against a full read.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_dir
from test_robust_logs import JOINTS, Tiny, cli, error_lines, keep, load_tum, rewrite, tiny  # noqa: F401

from fuzzyslam.config import load_config
from fuzzyslam.slam.log_setup import odom_cut_short
from fuzzyslam.streams.reader import LogMessage, LogReader

ROOT = Path(__file__).resolve().parents[1]
ODOM, TF = "/odom", "/tf"
IMAGE = "/ceiling_camera/image_raw"  # dropped from sample.mcap's copies (their size)


def cut(stop: dict[str, float], drop: tuple[str, ...] = (JOINTS,)):
    """A ``rewrite`` fault: ``drop`` left out; each topic of ``stop`` without its messages
    logged after its time (before it, for a negative time: -t starts the topic at t)."""

    def fault(m: LogMessage):
        if m.topic in drop:
            return []
        at = stop.get(m.topic)
        if at is not None and ((at >= 0 and m.t > at) or (at < 0 and m.t < -at)):
            return []
        return keep(m)

    return fault


@pytest.fixture(scope="session")
def tiny_odom(tiny: Tiny, tmp_path_factory) -> Path:  # noqa: F811
    """The tiny log read from its whole /odom (the encoders dropped: ``odom.mcap``) and
    its run (``est/``), built once per test run (tests/test_odometry_sources_*.py)."""

    def build(d: Path) -> None:
        log = rewrite(tiny.log, d / "odom.mcap", cut({}))
        code, out, err = cli("run", log, "-o", d / "est", "--config", tiny.config)
        assert code == 0, err
        assert json.loads(out)["odometry_source"] == "odom (/odom)"

    return shared_dir(tmp_path_factory, "odometry-sources-odom", build)


def test_a_partial_odom_is_passed_over_for_the_whole_tf(
    tiny: Tiny,  # noqa: F811
    tiny_odom: Path,
    tmp_path: Path,
) -> None:
    """/odom stops at 20 s of the 37.5 s log, /tf goes on: the odometry is read from
    /tf (the summary's odometry_source), said in one line with when /odom stopped; no
    frame is lost to a silent odometry and the trajectory is that of the whole /odom."""
    log = rewrite(tiny.log, tmp_path / "partial.mcap", cut({ODOM: 20.0}))
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    s = json.loads(out)
    assert s["odometry_source"] == "tf (/tf odom -> base_link)"
    assert s["counts"]["frames_stale_odometry"] == 0
    notes = [ln for ln in error_lines(err) if "note:" in ln]
    assert len(notes) == 1, err
    assert "/odom falls silent at 20.00 s of the log's 37.55 s" in notes[0]
    assert notes[0].endswith("the odometry is read from /tf's odom -> base_link transforms")
    assert "fell silent" not in err
    got, want = (
        load_tum(tmp_path / "est" / "trajectory.tum"),
        load_tum(tiny_odom / "est" / "trajectory.tum"),
    )
    assert got.shape == want.shape and len(got) > 50
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    "stop",
    [
        {ODOM: 37.0},  # /odom ends 0.55 s before the log: within a gap (1 s) of its end
        # ... 2.55 s before: over a gap, under a tenth of the log (3.75 s): a shutdown
        {ODOM: 35.0},
        {ODOM: 20.0, TF: 22.0},  # /tf goes on 2 s after /odom: under a tenth of the log
        {ODOM: 20.0, TF: 20.5},  # /tf stops with it: no whole odometry to read instead
        {ODOM: 20.0, TF: -5.0},  # /tf's starts 5 s late: it would lose the start
    ],
)
def test_odom_is_kept_unless_tf_covers_markedly_more(
    tiny: Tiny,  # noqa: F811
    tmp_path: Path,
    stop: dict[str, float],
) -> None:
    """/odom is read when it reaches within max(a gap, a tenth of the log's span) of the
    log's end, when /tf's odometry goes on less than that after /odom's end, or when
    /tf's starts later than /odom's by more than a gap. (The gap alone passed the
    whole run over to /tf for an /odom 2.55 s short of the log's end.)"""
    log = rewrite(tiny.log, tmp_path / "log.mcap", cut(stop))
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    assert json.loads(out)["odometry_source"] == "odom (/odom)"
    assert "falls silent at" not in err


def test_tf_need_not_reach_the_end(tiny: Tiny, tmp_path: Path) -> None:  # noqa: F811
    """/odom stops at 20 s, /tf's odometry at 30 s of the 37.55 s log: /tf goes on for
    10 s more than /odom (over a tenth of the log), so it is read, though it too stops
    before the log's end (``odom_cut_short`` directly: the choice, not the run)."""
    log = rewrite(tiny.log, tmp_path / "log.mcap", cut({ODOM: 20.0, TF: 30.0}))
    got = odom_cut_short(LogReader(log), load_config(tiny.config))
    assert got is not None and got[0].base == "base_link"
    assert "/odom falls silent at 20.00 s of the log's 37.55 s" in got[1]


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_the_reviewers_shortfall_of_sample_is_no_cut(tmp_path: Path) -> None:
    """The reviewer's case: data/sample.mcap without its encoders and /odom's last 2 s
    (of 121 s): /odom is read (the gap rule alone said "/odom falls silent at 119.05 s
    of the log's 121.05 s" and read the whole run from /tf); with /odom's last 20 s
    dropped (over a tenth of the log), /tf is."""
    src = ROOT / "data" / "sample.mcap"
    end = LogReader(src).end
    cfg = load_config("sample.yaml")
    two = rewrite(src, tmp_path / "two.mcap", cut({ODOM: end - 2.0}, drop=(JOINTS, IMAGE)))
    assert odom_cut_short(LogReader(two), cfg) is None
    twenty = rewrite(src, tmp_path / "twenty.mcap", cut({ODOM: end - 20.0}, drop=(JOINTS, IMAGE)))
    got = odom_cut_short(LogReader(twenty), cfg)
    assert got is not None and "falls silent at 101.0" in got[1]


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_last_time_is_the_last_message_of_the_topic(tiny: Tiny, tmp_path: Path) -> None:  # noqa: F811
    """``LogReader.last_time`` from the chunk indexes equals a full read's last log time
    for every topic of the small-chunk copy of the tiny log (many chunks), of a copy
    whose /odom stops early, and of the CARMEN excerpt; None for a topic not in it."""
    partial = rewrite(tiny.log, tmp_path / "p.mcap", cut({ODOM: 20.0}), chunk_size=64 * 1024)
    logs = [tiny.small_chunks, partial, ROOT / "data" / "carmen_fr079_excerpt" / "log.mcap"]
    for path in logs:
        reader = LogReader(path)
        for topic in reader.topics:
            want = max(m.t for m in reader.messages([topic]))
            assert reader.last_time(topic) == want, (path, topic)
        assert reader.last_time("/none") is None
    assert LogReader(partial).last_time(ODOM) <= 20.0 < LogReader(partial).last_time(TF)
