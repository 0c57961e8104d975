"""Robustness on damaged and glitched recordings (issue 7).

A tiny simulated log (a third of a lap, ~38 s) is made once per session; damaged
copies are cut from it at many byte offsets (property-based) or re-written with
``LogWriter`` with injected faults (``rewrite``), and the stages are run on them
in-process through ``fuzzyslam.cli.main`` (exit code, stdout and stderr as a user
sees them). Every test asserts the exit code, the one-line message or the
glitch counts of the summary, and that no partial output was left behind.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_dir
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from fuzzyslam.cli import main
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import MCAP_MAGIC, LogMessage, LogReader
from fuzzyslam.streams.writer import LogWriter

TINY_YAML = """\
extends: quick.yaml
name: tiny
scenario:
  runs: 1
  lap_fraction: 0.3
"""
SONAR = "/sonar/s"
IMAGE = "/ceiling_camera/image_raw"
JOINTS = "/joint_states"

Out = tuple[str, str, object, float]  # topic, type name, message, log time


# -- helpers ------------------------------------------------------------------------------


def cli(*args: str) -> tuple[int, str, str]:
    """Run ``fuzzyslam ARGS`` in-process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    code = 0
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([str(a) for a in args])
        except SystemExit as exc:
            code = int(exc.code or 0)
    return code, out.getvalue(), err.getvalue()


def error_lines(stderr: str) -> list[str]:
    """The lines of stderr that are not progress output (progress is off in tests)."""
    return [ln for ln in stderr.splitlines() if ln.strip()]


def leftovers(folder: Path) -> list[Path]:
    """Temporary files or directories (``.NAME.XXXX.part``) left in ``folder``."""
    return sorted(folder.glob(".*.part"))


def rewrite(
    src: Path,
    dst: Path,
    fault: Callable[[LogMessage], Iterable[Out]] | None = None,
    chunk_size: int = 1024 * 1024,
) -> Path:
    """Copy a log message by message (metadata first), passing each through ``fault``.

    ``fault(m)`` returns the messages to write instead of ``m`` (none to drop it, two
    to duplicate it, a changed one to corrupt it).
    """
    reader = LogReader(src)
    with LogWriter(dst, chunk_size=chunk_size) as w:
        for name in sorted(reader.metadata, key=lambda n: (n != "fuzzyslam.world", n)):
            w.metadata(name, reader.metadata[name])
        for m in reader.messages():
            for topic, typename, msg, t in (
                fault(m) if fault else [(m.topic, m.typename, m.msg, m.t)]
            ):
                w.write(topic, typename, msg, t)
    return dst


def keep(m: LogMessage) -> list[Out]:
    return [(m.topic, m.typename, m.msg, m.t)]


def set_stamp(msg, t: float) -> None:
    msg.header.stamp.sec = math.floor(t)
    msg.header.stamp.nanosec = round((t - math.floor(t)) * 1e9) % 1_000_000_000


def load_tum(path: Path) -> np.ndarray:
    return np.loadtxt(path, ndmin=2)


@dataclass
class Tiny:
    dir: Path
    config: Path
    log: Path
    small_chunks: Path
    est: Path
    run: dict
    map: dict


@pytest.fixture(scope="session")
def tiny(tmp_path_factory) -> Tiny:
    """A short simulated log, its run and its map, built once per test run
    (conftest.shared_dir); the tests only read them."""

    def build(d: Path) -> None:
        cfg = d / "tiny.yaml"
        cfg.write_text(TINY_YAML, encoding="utf-8")
        log = d / "tiny.mcap"
        code, _, err = cli("simulate", cfg, "-o", log)
        assert code == 0, err
        # 256 KiB chunks: more chunk boundaries for the truncation tests
        rewrite(log, d / "small_chunks.mcap", chunk_size=256 * 1024)
        code, out, err = cli("run", log, "-o", d / "est", "--config", cfg)
        assert code == 0, err
        (d / "run.json").write_text(out, encoding="utf-8")
        code, out, err = cli(
            "map", log, "--trajectory", d / "est" / "trajectory.tum", "-o", d / "fgm",
            "--config", cfg, "--no-figures",
        )  # fmt: skip
        assert code == 0, err
        (d / "map.json").write_text(out, encoding="utf-8")

    d = shared_dir(tmp_path_factory, "robust-tiny", build)
    run = json.loads((d / "run.json").read_text(encoding="utf-8"))
    mapped = json.loads((d / "map.json").read_text(encoding="utf-8"))
    return Tiny(
        d, d / "tiny.yaml", d / "tiny.mcap", d / "small_chunks.mcap", d / "est", run, mapped
    )


# -- not MCAP, random bytes ---------------------------------------------------------------


@given(data=st.binary(min_size=0, max_size=4096), magic=st.booleans())
@settings(max_examples=30, deadline=None)
def test_random_bytes_are_one_line_errors(tiny: Tiny, data: bytes, magic: bool) -> None:
    """Random bytes (with or without the MCAP magic in front): exit 3, one line naming
    the file, no output directory and no temporary left."""
    with tempfile.TemporaryDirectory() as td:
        log = Path(td) / "junk.mcap"
        log.write_bytes((MCAP_MAGIC if magic else b"") + data)
        out = Path(td) / "est"
        code, stdout, stderr = cli("run", log, "-o", out, "--config", tiny.config)
        lines = error_lines(stderr)
        assert code == 3, stderr
        assert len(lines) == 1 and lines[0].startswith(f"fuzzyslam: error: {log}: ")
        assert stdout == ""
        assert not out.exists() and not leftovers(Path(td))


def test_not_mcap_says_so(tiny: Tiny, tmp_path: Path) -> None:
    text = tmp_path / "notes.mcap"
    text.write_text("this is a text file, not a recording\n", encoding="utf-8")
    code, _, stderr = cli("run", text, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 3
    assert error_lines(stderr) == [f"fuzzyslam: error: {text}: not an MCAP file (bad magic bytes)"]


# -- truncation ---------------------------------------------------------------------------


def chunk_index(path: Path) -> list:
    from mcap.reader import SeekingReader

    with open(path, "rb") as f:
        summary = SeekingReader(f).get_summary()
    return sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset)


def chunk_offsets(path: Path) -> list[int]:
    return [c.chunk_start_offset for c in chunk_index(path)]


@pytest.mark.slow
def test_reader_reads_a_cut_log_as_far_as_it_is_intact(tiny: Tiny) -> None:
    """At a cut inside a chunk the whole records of the chunk's intact part are kept
    (salvaged); the messages read are exactly the first ones of the intact log, and
    a later cut never gives fewer messages."""
    data = tiny.log.read_bytes()
    full = [(m.topic, m.t) for m in LogReader(tiny.log).messages()]
    starts = chunk_offsets(tiny.log)  # 1 MiB chunks (uncompressed): zstd blocks of 128 KiB
    a, b = starts[1], starts[2]
    got = []
    with tempfile.TemporaryDirectory() as td:
        cut = Path(td) / "cut.mcap"
        for off in [a + (b - a) // 2, a + (b - a) * 9 // 10, b + 9, b]:
            cut.write_bytes(data[:off])
            r = LogReader(cut)
            msgs = [(m.topic, m.t) for m in r.messages()]
            assert msgs == full[: len(msgs)]
            d = r.damage()
            assert d["truncated"] and 0 <= d["lost_bytes"] <= off
            got.append((off, len(msgs), d["salvaged_messages"]))
    # inside a chunk: some of its messages were salvaged, more with a later cut
    assert got[0][2] > 0 and got[1][1] > got[0][1] > 0
    # at a chunk start nothing is salvaged and nothing after the previous chunk is lost
    assert got[3][2] == 0 and got[2][1] == got[3][1]


def _counted_walks(monkeypatch) -> list:
    """The record walks of logs without a summary from here on (their paths)."""
    from fuzzyslam.streams import reader as R

    walks = []
    real_walk = R.LogReader._walk_stream

    def counted(self):
        walks.append(self.path)
        return real_walk(self)

    monkeypatch.setattr(R.LogReader, "_walk_stream", counted)
    return walks


def test_readers_in_a_command_share_the_walk_of_a_log_without_summary(
    tiny: Tiny, tmp_path: Path, monkeypatch
) -> None:
    """Two readers of a log cut short (no summary) in one command: one record walk, and
    each reader its own damage count; a file that changed is walked again; outside a
    command every reader walks."""
    import os

    from fuzzyslam.streams import reader as R

    data = tiny.small_chunks.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 9 // 10])
    walks = _counted_walks(monkeypatch)
    # two readers in one command: one walk; each its own damage count, equal
    with R.shared_walks():
        a, b = R.LogReader(cut), R.LogReader(cut)
        assert len(walks) == 1 and a.damage() == b.damage() and a.damage()["truncated"]
        assert a.damage_state() is not b.damage_state()
        assert (a.topics, a.counts, a.start, a.end) == (b.topics, b.counts, b.start, b.end)
        st = cut.stat()
        os.utime(cut, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # the file changed
        R.LogReader(cut)
        assert len(walks) == 2
    R.LogReader(cut)  # outside a command: a walk per reader
    assert len(walks) == 3


@pytest.mark.slow  # two commands and the same two stage calls: 3-5 s
def test_a_command_walks_a_log_without_summary_once(
    tiny: Tiny, tmp_path: Path, monkeypatch
) -> None:
    """``run`` and ``map`` open their log several times (the preset's or the map's
    config, the aids, the inputs): a log cut short (no summary) was walked each time.
    Now one walk serves the command, and the outputs are byte for byte those of the
    stages called outside a command (a walk per reader)."""
    from fuzzyslam.maps.stage import run as map_stage
    from fuzzyslam.slam.stage import run as run_stage

    data = tiny.small_chunks.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 9 // 10])
    walks = _counted_walks(monkeypatch)
    # run with a map (its config, the fixes' aids, the inputs) and map without --config
    # (the preset's choice, the rings): two walks each outside a command
    fgm, traj = tiny.dir / "fgm", tiny.est / "trajectory.tum"
    for name, argv, stage, kwargs, files in [
        ("run", ("run", cut, "-o", tmp_path / "run", "--map", fgm, "--fix", "pose",
                 "--no-prefetch"),
         run_stage, {"log": cut, "outdir": tmp_path / "run_2", "map_dir": fgm, "fix": "pose"},
         ("trajectory.tum", "covariance.csv", "landmarks.yaml")),
        ("map", ("map", cut, "--trajectory", traj, "-o", tmp_path / "map", "--no-figures"),
         map_stage, {"log": cut, "trajectory": traj, "outdir": tmp_path / "map_2",
                     "figures": False},
         ("fgm.npz", "fgm.pgm", "references.yaml")),
    ]:  # fmt: skip
        walks.clear()
        code, out, err = cli(*argv)
        assert code == 0, err
        assert len(walks) == 1, name
        walks.clear()
        summary = stage(**kwargs)
        assert len(walks) == 2, name  # what the command did before
        assert json.loads(out)["log_damage"] == summary["log_damage"]
        for f in files:
            assert (tmp_path / name / f).read_bytes() == (tmp_path / f"{name}_2" / f).read_bytes()


def test_damaged_chunk_in_the_middle_is_skipped_and_counted(tiny: Tiny, tmp_path: Path) -> None:
    """Bytes overwritten inside one chunk's compressed data and the summary gone: the
    chunk is counted as damaged, the chunks after it are still read."""
    data = bytearray(tiny.small_chunks.read_bytes())
    chunks = chunk_index(tiny.small_chunks)
    a = chunks[4].chunk_start_offset + 200
    data[a : a + 64] = bytes(64)  # corrupt the zstd stream of chunk 4
    bad = tmp_path / "damaged.mcap"
    bad.write_bytes(bytes(data[: len(data) - 100]))  # and lose the footer
    r = LogReader(bad)
    msgs = [(m.topic, m.t) for m in r.messages()]
    full = [(m.topic, m.t) for m in LogReader(tiny.small_chunks).messages()]
    d = r.damage()
    assert d["truncated"] and d["damaged_records"] == 1
    assert d["lost_bytes"] == chunks[4].chunk_length  # the cut fell in the summary section
    assert 0 < len(msgs) < len(full) and set(msgs) <= set(full)
    assert msgs[-1] == full[-1]  # read to the end past the damaged chunk


def test_damaged_chunk_with_intact_index_is_skipped_and_counted(tiny: Tiny, tmp_path: Path) -> None:
    """A chunk whose data is corrupt (CRC mismatch) in a file whose summary is intact:
    run and map skip that chunk, count it in log_damage, and use every other one."""
    data = bytearray(tiny.small_chunks.read_bytes())
    chunks = chunk_index(tiny.small_chunks)
    a = chunks[3].chunk_start_offset + 5000
    data[a : a + 64] = bytes(64)
    bad = tmp_path / "bad_chunk.mcap"
    bad.write_bytes(bytes(data))
    s = run_json(tiny, bad, tmp_path / "est")
    assert s["log_damage"]["damaged_records"] == 1 and not s["log_damage"]["truncated"]
    assert s["log_damage"]["lost_bytes"] == chunks[3].chunk_length
    assert 0 < s["counts"]["frames"] < tiny.run["counts"]["frames"]
    m = map_json(tiny, bad, tmp_path / "fgm")
    assert m["log_damage"]["damaged_records"] == 1
    assert 0 < m["rings_used"] < tiny.map["rings_used"]


@pytest.mark.slow
@given(frac=st.floats(0.0, 1.0))
@example(frac=0.0)
@example(frac=0.001)
@example(frac=0.999)
@example(frac=1.0)
@settings(
    max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
def test_truncated_log_runs_with_every_complete_message(tiny: Tiny, frac: float) -> None:
    """``run`` on the log cut at any byte: either one line and exit 3 (nothing readable)
    and no output, or success whose summary counts the loss and whose trajectory is
    the full run's trajectory up to the cut (the filter is causal)."""
    data = tiny.small_chunks.read_bytes()
    off = int(frac * len(data))
    full = load_tum(tiny.est / "trajectory.tum")
    with tempfile.TemporaryDirectory() as td:
        log = Path(td) / "cut.mcap"
        log.write_bytes(data[:off])
        out = Path(td) / "est"
        code, stdout, stderr = cli("run", log, "-o", out, "--config", tiny.config)
        assert not leftovers(Path(td))
        if code != 0:
            lines = error_lines(stderr)
            assert code == 3 and len(lines) == 1, stderr
            assert lines[0].startswith(f"fuzzyslam: error: {log}: ")
            assert not out.exists()
            return
        summary = json.loads(stdout)
        dmg = summary["log_damage"]
        assert dmg["truncated"] == (off < len(data))
        assert 0 <= dmg["lost_bytes"] <= off
        traj = load_tum(out / "trajectory.tum")
        n = len(traj) - 1  # the last row is the state at the last event read
        assert n <= len(full)
        np.testing.assert_allclose(traj[:n], full[:n], rtol=0, atol=1e-9)
        assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in tiny.est.iterdir())


@pytest.mark.slow
@given(frac=st.floats(0.05, 1.0))
@settings(max_examples=8, deadline=None)
def test_truncated_log_maps_with_every_complete_ring(tiny: Tiny, frac: float) -> None:
    """``map`` on a cut log: the rings used are the full map's first rings; the summary
    counts the loss; failures are one line with no output."""
    data = tiny.small_chunks.read_bytes()
    off = int(frac * len(data))
    with tempfile.TemporaryDirectory() as td:
        log = Path(td) / "cut.mcap"
        log.write_bytes(data[:off])
        out = Path(td) / "fgm"
        code, stdout, stderr = cli(
            "map", log, "--trajectory", tiny.est / "trajectory.tum", "-o", out,
            "--config", tiny.config, "--no-figures",
        )  # fmt: skip
        assert not leftovers(Path(td))
        if code != 0:
            lines = error_lines(stderr)
            assert code == 3 and len(lines) == 1 and str(log) in lines[0], stderr
            assert not out.exists()
            return
        s = json.loads(stdout)
        assert s["log_damage"]["truncated"] == (off < len(data))
        assert 0 < s["rings_used"] <= tiny.map["rings_used"]
        with np.load(out / "fgm.npz") as z:
            masses = sum(z[k].astype(float) for k in ("m_e", "m_o", "m_t", "m_c"))
        np.testing.assert_allclose(masses, 1.0, atol=1e-5)


# -- glitches -----------------------------------------------------------------------------


class Every:
    """Pick every ``n``-th message of topics starting with ``prefix`` (and ``cond``)."""

    def __init__(self, prefix: str, n: int, cond: Callable[[LogMessage], bool] = lambda m: True):
        self.prefix, self.n, self.cond, self.seen, self.hits = prefix, n, cond, 0, 0

    def __call__(self, m: LogMessage) -> bool:
        if not m.topic.startswith(self.prefix) or not self.cond(m):
            return False
        self.seen += 1
        if self.seen % self.n:
            return False
        self.hits += 1
        return True


def run_json(tiny: Tiny, log: Path, out: Path) -> dict:
    code, stdout, stderr = cli("run", log, "-o", out, "--config", tiny.config)
    assert code == 0, stderr
    assert not leftovers(out.parent)
    return json.loads(stdout)


def map_json(tiny: Tiny, log: Path, out: Path) -> dict:
    code, stdout, stderr = cli(
        "map", log, "--trajectory", tiny.est / "trajectory.tum", "-o", out,
        "--config", tiny.config, "--no-figures",
    )  # fmt: skip
    assert code == 0, stderr
    with np.load(out / "fgm.npz") as z:
        masses = [z[k].astype(float) for k in ("m_e", "m_o", "m_t", "m_c")]
    assert all(np.all(np.isfinite(m)) and np.all(m >= 0) for m in masses)
    np.testing.assert_allclose(sum(masses), 1.0, atol=1e-5)
    return json.loads(stdout)


def test_sonar_glitches_are_counted_never_used(tiny: Tiny, tmp_path: Path) -> None:
    """NaN, infinite, negative and far out-of-range echoes and repeated messages: the
    map counts each exactly (invalid, no_echo, duplicates) and its masses stay valid.
    +inf is REP 117's "nothing detected": no echo, as a range beyond max_range."""
    echo = Every(SONAR, 6, lambda m: 0 < m.msg.range < m.msg.max_range)
    dup = Every(SONAR, 40)
    bad = [math.nan, math.inf, -1.0, 1e6]
    kinds: list[float] = []

    def fault(m: LogMessage) -> list[Out]:
        if echo(m):
            m.msg.range = bad[len(kinds) % 4]
            kinds.append(m.msg.range)
        return keep(m) * (2 if dup(m) else 1)

    log = rewrite(tiny.log, tmp_path / "sonar.mcap", fault)
    s = map_json(tiny, log, tmp_path / "fgm")["sonar_stats"]
    clean = tiny.map["sonar_stats"]
    n_big = sum(k in (1e6, math.inf) for k in kinds)
    assert echo.hits > 20 and dup.hits > 10
    assert s["invalid"] == clean["invalid"] + len(kinds) - n_big
    assert s["no_echo"] == clean["no_echo"] + n_big
    assert s["duplicates"] == clean["duplicates"] + dup.hits
    assert s["readings"] == clean["readings"]
    assert s["rings"] == clean["rings"] and s["missing"] == clean["missing"]


def test_a_rep117_sonar_log_maps_as_its_max_range_twin(tiny: Tiny, tmp_path: Path) -> None:
    """Every no-echo reading (range at max_range, as the simulator writes them) published
    as +inf, as a REP 117 driver does: the same sonar statistics and the same map, cell
    for cell (it once read +inf as invalid: 40 % of the readings lost)."""

    def fault(m: LogMessage) -> list[Out]:
        if m.topic.startswith(SONAR) and m.msg.range >= m.msg.max_range:
            m.msg.range = math.inf
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "inf.mcap", fault)
    s = map_json(tiny, log, tmp_path / "fgm")["sonar_stats"]
    assert s == tiny.map["sonar_stats"] and s["no_echo"] > 100
    with np.load(tmp_path / "fgm" / "fgm.npz") as a, np.load(tiny.dir / "fgm" / "fgm.npz") as b:
        for k in ("m_e", "m_o", "m_t", "m_c"):
            np.testing.assert_array_equal(a[k], b[k])


def test_frame_glitches_are_counted_and_skipped(tiny: Tiny, tmp_path: Path) -> None:
    """Empty, wrongly sized and wrongly encoded frames: each counted in bad_frames,
    skipped, and the lamps found are the clean run's."""
    pick = Every(IMAGE, 9)

    def fault(m: LogMessage) -> list[Out]:
        if pick(m):
            kind = pick.hits % 3
            if kind == 0:
                m.msg.data = np.zeros(0, dtype=np.uint8)
            elif kind == 1:
                m.msg.data = m.msg.data[: len(m.msg.data) // 2]
            else:
                m.msg.encoding = "rgb8"
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "frames.mcap", fault)
    s = run_json(tiny, log, tmp_path / "est")
    assert pick.hits >= 15
    assert s["warnings"]["bad_frames"] == pick.hits
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"] - pick.hits
    assert s["lamps"] == tiny.run["lamps"]


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_stamps_back_in_time_and_repeated_are_counted(tiny: Tiny, tmp_path: Path) -> None:
    """Header stamps that go back in time and repeated messages (same stamp) are dropped
    and counted once each; the final pose barely moves (wheel angles are cumulative: the
    next message carries a dropped one's motion). The dead reckoning written has strictly
    increasing stamps, so ``evaluate`` reads it."""
    js = Every(JOINTS, 25)
    img = Every(IMAGE, 17)
    js_dup = Every(JOINTS, 33)
    img_dup = Every(IMAGE, 21)

    def fault(m: LogMessage) -> list[Out]:
        if js(m):
            set_stamp(m.msg, m.t - 0.5)
        elif img(m):
            set_stamp(m.msg, m.t - 1.0)
        elif js_dup(m) or img_dup(m):
            return keep(m) * 2
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "stamps.mcap", fault)
    s = run_json(tiny, log, tmp_path / "est")
    assert s["warnings"]["out_of_order"] == js.hits + img.hits
    assert s["warnings"]["duplicate_stamps"] == js_dup.hits + img_dup.hits
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"] - img.hits
    d = np.subtract(s["final_pose"][:2], tiny.run["final_pose"][:2])
    assert np.hypot(*d) < 3 * max(tiny.run["final_pose_sigma"][:2])
    for name in ("odometry.tum", "trajectory.tum"):
        assert np.all(np.diff(load_tum(tmp_path / "est" / name)[:, 0]) > 0), name
    code, _, err = cli("evaluate", log, tmp_path / "est", "-o", tmp_path / "ev")
    assert code == 0, err


def lag_frames(lag: float) -> Callable[[LogMessage], list[Out]]:
    """A fault: every camera frame logged ``lag`` s after its exposure (its header stamp
    unchanged), as a recorder logs the output of an image pipeline that lags."""

    def fault(m: LogMessage) -> list[Out]:
        return [(m.topic, m.typename, m.msg, m.t + lag)] if m.topic == IMAGE else keep(m)

    return fault


def test_frames_logged_late_are_put_back_in_stamp_order(tiny: Tiny, tmp_path: Path) -> None:
    """Frames logged 0.8 s after their exposure, behind odometry stamped later: the
    filter takes them in header-stamp order, so the run is the clean run, file for file."""
    log = rewrite(tiny.log, tmp_path / "late.mcap", lag_frames(0.8))
    s = run_json(tiny, log, tmp_path / "est")
    assert s["warnings"]["reordered"] >= s["counts"]["frames"] > 0
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"]
    assert s["counts"]["out_of_order"] == 0
    assert not s["filter_health"]["diverged"]
    for name in ("trajectory.tum", "odometry.tum", "covariance.csv", "landmarks.yaml"):
        assert (tmp_path / "est" / name).read_bytes() == (tiny.est / name).read_bytes(), name


@pytest.mark.slow
def test_frames_on_another_clock_are_not_used_and_said(tiny: Tiny, tmp_path: Path) -> None:
    """From 15 s on, the camera's frames are logged 7 s after their stamps (a pipeline
    that stalls, or a camera clock 7 s behind): beyond the 5 s window they cannot be
    placed, so they are not used, counted (clock_mismatch), the first described, and the
    summary says the filter is in trouble (events_lost) rather than healthy. All of them
    so: no usable frame, one line naming the clock."""

    def stall(m: LogMessage) -> list[Out]:
        late = m.topic == IMAGE and m.t >= 15.0
        return [(m.topic, m.typename, m.msg, m.t + 7.0)] if late else keep(m)

    log = rewrite(tiny.log, tmp_path / "stall.mcap", stall)
    s = run_json(tiny, log, tmp_path / "est")
    lost = s["warnings"]["clock_mismatch"]
    assert lost > 0.3 * tiny.run["counts"]["frames"]
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"] - lost
    assert "another clock" in s["first_warning"] and IMAGE in s["first_warning"]
    health = s["filter_health"]
    assert health["diverged"] and "events_lost" in health["reasons"]
    assert 14.9 < health["diverged_at"] < 15.1 + 7.0
    times = load_tum(tmp_path / "est" / "trajectory.tum")[:, 0]
    assert np.all(np.diff(times) > 0)
    # every frame 7 s late: nothing to use, one line
    log = rewrite(tiny.log, tmp_path / "late.mcap", lag_frames(7.0))
    code, out, err = cli("run", log, "-o", tmp_path / "none", "--config", tiny.config)
    assert code == 3 and out == "" and not (tmp_path / "none").exists()
    (line,) = error_lines(err)
    assert "no usable camera frame" in line and "another clock" in line


@pytest.mark.slow  # end to end, 1-3 s: the fast tier stays under a minute
def test_frames_stamped_before_the_log_starts_keep_the_trajectory_in_order(
    tiny: Tiny, tmp_path: Path
) -> None:
    """Every frame stamped 0.3 s before it was logged (exposure to recording): the first
    one is stamped before the log's first message, so the run starts there; the
    trajectory's stamps increase and evaluate reads it."""

    def early(m: LogMessage) -> list[Out]:
        if m.topic == IMAGE:
            set_stamp(m.msg, m.t - 0.3)
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "early.mcap", early)
    s = run_json(tiny, log, tmp_path / "est")
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"]
    assert not s["filter_health"]["diverged"]
    times = load_tum(tmp_path / "est" / "trajectory.tum")[:, 0]
    assert times[0] == pytest.approx(-0.3) and np.all(np.diff(times) > 0)
    code, _, err = cli("evaluate", log, tmp_path / "est", "-o", tmp_path / "ev")
    assert code == 0, err


def test_nan_odometry_is_counted(tiny: Tiny, tmp_path: Path) -> None:
    pick = Every(JOINTS, 30)

    def fault(m: LogMessage) -> list[Out]:
        if pick(m):
            m.msg.position = np.full_like(m.msg.position, np.nan)
        return keep(m)

    s = run_json(tiny, rewrite(tiny.log, tmp_path / "nan.mcap", fault), tmp_path / "est")
    assert s["warnings"]["nan_odometry"] == pick.hits
    assert s["counts"]["odometry"] <= tiny.run["counts"]["odometry"] - pick.hits


def test_odometry_gap_loses_no_motion(tiny: Tiny, tmp_path: Path) -> None:
    """Three seconds without /joint_states: the wheel angles are cumulative, so the
    motion across the gap is one increment; the final pose stays near the clean one."""

    def fault(m: LogMessage) -> list[Out]:
        return [] if m.topic == JOINTS and 10.0 < m.t < 13.0 else keep(m)

    s = run_json(tiny, rewrite(tiny.log, tmp_path / "gap.mcap", fault), tmp_path / "est")
    assert s["warnings"]["odometry_gaps"] == 1
    assert s["filter_health"]["odometry_gap_s"] == pytest.approx(3.0, abs=0.11)
    d = np.subtract(s["final_pose"][:2], tiny.run["final_pose"][:2])
    assert np.hypot(*d) < 0.05
    assert s["counts"]["odometry"] < tiny.run["counts"]["odometry"] - 50


def test_flickering_lamps_make_no_duplicates(tiny: Tiny, tmp_path: Path) -> None:
    """The leftmost lamp in view dark in every other frame (its whole blob erased):
    no extra lamp is created and the final pose stays near the clean run's."""
    import cv2

    pick = Every(IMAGE, 2)

    def fault(m: LogMessage) -> list[Out]:
        if pick(m):
            img = np.asarray(m.msg.data, dtype=np.uint8).reshape(m.msg.height, m.msg.step).copy()
            lit = (img > 100).astype(np.uint8)  # the background is ~36 grey levels
            n, labels, _, centroids = cv2.connectedComponentsWithStats(lit)
            if n > 1:
                blob = (labels == 1 + int(np.argmin(centroids[1:, 0]))).astype(np.uint8)
                img[cv2.dilate(blob, np.ones((5, 5), np.uint8)) > 0] = 36
            m.msg.data = img.reshape(-1)
        return keep(m)

    s = run_json(tiny, rewrite(tiny.log, tmp_path / "flicker.mcap", fault), tmp_path / "est")
    assert s["lamps"] == tiny.run["lamps"]
    assert s["counts"]["detections"] < tiny.run["counts"]["detections"] - 50
    d = np.subtract(s["final_pose"][:2], tiny.run["final_pose"][:2])
    assert np.hypot(*d) < 3 * max(tiny.run["final_pose_sigma"][:2]) + 0.02


# -- filter health in the summary ---------------------------------------------------------


def test_clean_run_is_healthy(tiny: Tiny) -> None:
    h = tiny.run["filter_health"]
    assert not h["diverged"] and h["p_repaired"] == 0
    assert h["nis_windows"] >= 3 and h["nis_windows_out_of_bounds"] == 0
    assert h["association_windows"] >= 3 and h["association_windows_out_of_bounds"] == 0
    assert tiny.run["log_damage"]["truncated"] is False


@pytest.mark.parametrize("relocalise", [False, True])
@pytest.mark.parametrize("scale", [0.9, 1.2])
def test_divergence_is_detected_and_reported(
    tiny: Tiny, tmp_path: Path, scale: float, relocalise: bool
) -> None:
    """A wheel radius 10-20 % off in the filter's config: the odometry drifts faster than
    its noise model admits, detections stop matching the mapped lamps and duplicates
    pile up; the summary says the filter diverged (exit 0: the outputs are kept, but
    flagged) instead of returning silent garbage. With the relocalisation test (the
    paper configs', docs/models.md sec. 4c) the drift is taken out frame after frame and
    duplicates do not pile up, but every relocalised frame counts as unexplained in the
    association windows: the model is still flagged."""
    from fuzzyslam.config import load_config

    r = load_config(tiny.config).robot.wheel_radius * scale
    cfg = tmp_path / "wrong.yaml"
    off = "" if relocalise else "slam: {relocalise_sigma_m: 0, relocalise_sigma_heading_deg: 0}\n"
    cfg.write_text(TINY_YAML + f"robot: {{wheel_radius: {r}}}\n" + off, encoding="utf-8")
    code, out, err = cli("run", tiny.log, "-o", tmp_path / "est", "--config", cfg)
    assert code == 0, err
    s = json.loads(out)
    h = s["filter_health"]
    assert h["diverged"] and 0 < h["diverged_at"] <= s["log_duration_s"] + 1e-6
    assert h["association_windows_out_of_bounds"] >= 3
    if relocalise:
        assert s["counts"]["relocalisations"] > 0.5 * s["counts"]["frames"]
        assert s["lamps"] < 2 * tiny.run["lamps"]  # no pile-up (a few duplicates at 20 %)
    else:
        assert s["lamps"] > 3 * tiny.run["lamps"]  # what the flag warns about


def test_map_ring_table_keeps_every_reading_exactly(tiny: Tiny, monkeypatch) -> None:
    """``map`` keeps its rings in float32 blocks (memory, issue 7): with 5-ring blocks
    (many boundaries) the table holds exactly the rings of ``group_rings`` (float32 is
    lossless for Range fields), so the map stage fuses the same float64 values."""
    from fuzzyslam.config import load_config
    from fuzzyslam.maps import build
    from fuzzyslam.streams.sonar import group_rings

    cfg = load_config(str(tiny.config))
    reader = LogReader(tiny.log)
    topics = [cfg.topics.sonar(i) for i in range(cfg.sonar.count)]
    index = {tp: i for i, tp in enumerate(topics)}
    rings = list(group_rings(reader.messages(topics), index, cfg.sonar.count))
    monkeypatch.setattr(build._RingTable, "block", 5)
    t_end = rings[-3].t  # a window ending inside a block
    times, ranges, rmax, *_, offsets = build.read_rings_compact(reader, cfg, t_end)
    rings = rings[:-2]
    assert ranges.dtype == np.float32 and len(times) == len(rings) > 20
    assert len(rings) % 5 != 0
    assert np.array_equal(times, [r.t for r in rings])
    assert np.array_equal(ranges.astype(float), [r.ranges for r in rings], equal_nan=True)
    assert np.array_equal(rmax.astype(float), [r.max_range for r in rings], equal_nan=True)
    assert not offsets.any()  # rings stamped alike: every reading at its ring's time


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_a_clock_step_is_followed_and_a_glitched_stamp_skipped(tiny: Tiny, tmp_path: Path) -> None:
    """Every stamp from 15 s on 10 s back (the robot's clock corrected while the recorder
    kept its own): the step is followed, said once, and no stream is taken for another
    clock (the 10 s stamped again are back in time: lost and counted). One odometry
    message stamped a million seconds off: skipped as a glitch, no odometry gap."""

    def step(m: LogMessage) -> list[Out]:
        if m.t >= 15.0 and hasattr(m.msg, "header"):
            set_stamp(m.msg, M.stamp_to_sec(m.msg.header.stamp) - 10.0)
        return keep(m)

    s = run_json(tiny, rewrite(tiny.log, tmp_path / "step.mcap", step), tmp_path / "step")
    assert s["warnings"]["clock_steps"] == 1 and "clock_mismatch" not in s["warnings"]
    assert (
        "stamps stepped -10.000 s" in s["first_warning"]
        or "stamped -10.000 s" in s["first_warning"]
    )
    glitch = Every(JOINTS, 200)

    def one(m: LogMessage) -> list[Out]:
        if glitch(m) and glitch.hits == 1:
            set_stamp(m.msg, m.t + 1e6)
        return keep(m)

    s = run_json(tiny, rewrite(tiny.log, tmp_path / "glitch.mcap", one), tmp_path / "glitch")
    assert s["warnings"]["odometry_clock_glitches"] == 1
    assert "odometry_gaps" not in s["warnings"] and "clock_steps" not in s["warnings"]
    d = np.subtract(s["final_pose"][:2], tiny.run["final_pose"][:2])
    assert np.hypot(*d) < 0.05


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_stamps_from_zero_in_a_unix_time_log_give_increasing_tum_rows(
    tiny: Tiny, tmp_path: Path
) -> None:
    """A log recorded in Unix time whose header stamps start at 0 (a simulator's clock on
    a wall-clock recorder): the run's start row is on the stamps' clock, so odometry.tum
    and trajectory.tum stamps increase strictly (``evaluate`` reads them) and start at the
    first odometry stamp, not at the first increment's."""
    from fuzzyslam.streams.tum import read_tum

    unix = 1.6e9

    def shift(m: LogMessage) -> list[Out]:
        return [(m.topic, m.typename, m.msg, m.t + unix)]

    log = rewrite(tiny.log, tmp_path / "unix.mcap", shift)
    code, _, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    for name in ("odometry.tum", "trajectory.tum"):
        t, _ = read_tum(tmp_path / "est" / name)  # strictly increasing, or an error
        assert 0.0 <= t[0] < 0.06 and np.all(np.diff(t) > 0), name
    code, _, err = cli("evaluate", tiny.log, tmp_path / "est", "-o",
                       tmp_path / "eval")  # fmt: skip
    assert code == 0, err


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_frames_before_the_odometry_starts_are_not_used(tiny: Tiny, tmp_path: Path) -> None:
    """The odometry's first 5 s not logged (a driver started late): the camera frames
    stamped more than odometry_stale_s before its first message were taken where the
    robot's pose is unknown; they are counted and not used (before, they were fused as
    if the robot stood at the start pose), and the trajectory starts with the first
    frame that can be placed."""
    import json

    def late_odometry(m: LogMessage) -> list[Out]:
        return [] if m.topic == JOINTS and m.t < 5.0 else keep(m)

    log = rewrite(tiny.log, tmp_path / "late.mcap", late_odometry)
    first_odometry = next(m.t for m in LogReader(log).messages([JOINTS]))
    frames_before = sum(m.t < first_odometry - 1.0 for m in LogReader(log).messages([IMAGE]))
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    s = json.loads(out)
    assert frames_before > 5
    assert s["warnings"]["frames_before_odometry"] == frames_before
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"] - frames_before
    t = load_tum(tmp_path / "est" / "trajectory.tum")[:, 0]
    assert first_odometry - 1.0 <= t[0] < first_odometry
    # with the map's fixes: the sonar readings of that time are left out too
    code, out, err = cli("run", log, "-o", tmp_path / "fix", "--config", tiny.config, "--map",
                         tiny.dir / "fgm", "--fix", "heading", "--fix-from", "0")  # fmt: skip
    assert code == 0, err
    s = json.loads(out)
    assert s["warnings"]["readings_before_odometry"] > 16  # a whole ring at least
    t = load_tum(tmp_path / "fix" / "trajectory.tum")[:, 0]
    assert first_odometry - 1.0 <= t[0] < first_odometry


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_a_ros2_bag_folder_is_read_and_a_split_bag_is_said(tiny: Tiny, tmp_path: Path) -> None:
    """The folder ``ros2 bag record -s mcap`` writes (metadata.yaml and NAME_0.mcap) is
    read as its one MCAP file; a bag split into two files, or a folder without one, is
    one line saying what to do (before: "log is not a regular file")."""
    import shutil

    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n", encoding="utf-8")
    shutil.copy(tiny.log, bag / "bag_0.mcap")
    code, _, err = cli("run", bag, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 0, err
    assert (tmp_path / "est" / "trajectory.tum").read_bytes() == (
        tiny.est / "trajectory.tum"
    ).read_bytes()
    code, _, err = cli("evaluate", bag, tmp_path / "est", "-o", tmp_path / "eval")  # the truth
    assert code == 0, err
    shutil.copy(tiny.log, bag / "bag_1.mcap")
    code, _, err = cli("run", bag, "-o", tmp_path / "est2", "--config", tiny.config)
    assert code == 3 and "split into 2 files" in err and "mcap merge" in err
    assert len(err.strip().splitlines()) == 1
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = cli("run", empty, "-o", tmp_path / "est3", "--config", tiny.config)
    assert code == 3 and "no .mcap file" in err


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_a_run_folder_is_not_taken_for_a_bag(tiny: Tiny, tmp_path: Path) -> None:
    """A run's output folder (its trajectory.tum, its estimates.mcap) given as the log is
    one line saying so, not read as a bag of its estimates; a bag folder without
    metadata.yaml is a bag for ``evaluate`` too."""
    import shutil

    code, _, err = cli("run", tiny.est, "-o", tmp_path / "est", "--config", tiny.config)
    assert code == 3 and "run's output folder" in err and len(err.strip().splitlines()) == 1
    bag = tmp_path / "bag"
    bag.mkdir()
    shutil.copy(tiny.log, bag / "bag_0.mcap")
    code, _, err = cli("evaluate", bag, tiny.est, "-o", tmp_path / "eval")
    assert code == 0, err
