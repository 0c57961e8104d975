"""Silent wrong results (issue 14, class 4): sensor values no robot can produce are
rejected and counted, never used; a camera no pinhole model fits is a bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import test_robust_logs
from test_robust_logs import (
    JOINTS,
    SONAR,
    Every,
    LogMessage,
    Out,
    cli,
    error_lines,
    keep,
    map_json,
    rewrite,
)

from fuzzyslam.errors import EXIT_INPUT

pytestmark = pytest.mark.slow  # whole runs on simulated logs with injected sensor glitches

tiny = test_robust_logs.tiny  # the session fixture: a short simulated log, its run and map
INFO = "/ceiling_camera/camera_info"
IMAGE = "/ceiling_camera/image_raw"


def run_summary(tiny, log: Path, out: Path) -> dict:
    code, stdout, stderr = cli("run", log, "-o", out, "--config", tiny.config)
    assert code == 0, stderr
    return json.loads(stdout)


@pytest.mark.parametrize("jump", [1e6, -1e6, 1e300, 50.0])
def test_one_odometry_spike_is_rejected(tiny, tmp_path: Path, jump: float) -> None:
    """One JointState whose left wheel angle jumps by ``jump`` rad (and comes back):
    rejected and counted once; the estimate ends where the clean run ends (it was a
    LinAlgError at +1e6 and a pose 1 km away at +1e300)."""
    pick = Every(JOINTS, 200)

    def fault(m: LogMessage) -> list[Out]:
        if pick(m) and pick.hits == 1:
            m.msg.position = m.msg.position + np.array([jump, 0.0])
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "spike.mcap", fault)
    s = run_summary(tiny, log, tmp_path / "est")
    assert pick.hits >= 1
    assert s["warnings"]["implausible_odometry"] == 1
    end, clean = np.array(s["final_pose"]), np.array(tiny.run["final_pose"])
    assert np.hypot(*(end[:2] - clean[:2])) < 0.01
    assert s["filter_health"].get("diverged") is not True


def test_encoder_reset_restarts_from_the_new_reading(tiny, tmp_path: Path) -> None:
    """The left wheel counter jumps by 1000 rad for good (a reset): a few increments are
    rejected, then the latest reading becomes the reference; the run stays near the
    clean one (a few increments of motion lost), and both are counted."""
    state = {"n": 0}

    def fault(m: LogMessage) -> list[Out]:
        if m.topic == JOINTS:
            state["n"] += 1
            if state["n"] > 100:
                m.msg.position = m.msg.position + np.array([1000.0, 0.0])
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "reset.mcap", fault)
    s = run_summary(tiny, log, tmp_path / "est")
    assert s["warnings"]["odometry_reanchored"] == 1
    assert s["warnings"]["implausible_odometry"] == 5
    end, clean = np.array(s["final_pose"]), np.array(tiny.run["final_pose"])
    assert np.hypot(*(end[:2] - clean[:2])) < 0.2


def _set_k(msg, fx: float, fy: float, cx: float | None = None) -> None:
    k = np.array(msg.k, dtype=float)
    k[0], k[4] = fx, fy
    if cx is not None:
        k[2] = cx
    msg.k = k


CAMERAS = {
    "fx zero": lambda k: (0.0, k[4], None),
    "fx negative": lambda k: (-k[0], -k[4], None),
    "fy different": lambda k: (k[0], 2.0 * k[4], None),
    "focal inf": lambda k: (np.inf, np.inf, None),
    "focal 1e300": lambda k: (1e300, 1e300, None),
    "focal tiny": lambda k: (1e-6, 1e-6, None),
    "cx nan": lambda k: (k[0], k[4], np.nan),
    "cx off the image": lambda k: (k[0], k[4], 1e6),
}


@pytest.mark.parametrize("kind", sorted(CAMERAS))
def test_impossible_camera_info_is_a_bad_input(tiny, tmp_path: Path, kind: str) -> None:
    """A CameraInfo no pinhole ceiling camera can have: exit 3, one line naming the
    log and the camera_info topic (it ran on with 0 or 180 lamps before)."""

    def fault(m: LogMessage) -> list[Out]:
        if m.topic == INFO:
            _set_k(m.msg, *CAMERAS[kind](np.array(m.msg.k, dtype=float)))
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "cam.mcap", fault)
    code, out, err = cli("run", log, "-o", tmp_path / "est", "--config", tiny.config)
    lines = error_lines(err)
    assert code == EXIT_INPUT, err
    assert len(lines) == 1 and lines[0].startswith(f"fuzzyslam: error: {log}: {INFO}: ")
    assert out == "" and not (tmp_path / "est").exists()


def test_frames_of_another_size_are_bad_frames(tiny, tmp_path: Path) -> None:
    """Frames whose size differs from the CameraInfo's: counted as bad frames, not
    unprojected with the wrong principal point."""
    pick = Every(IMAGE, 7)

    def fault(m: LogMessage) -> list[Out]:
        if pick(m):
            w, h = m.msg.width // 2, m.msg.height // 2
            m.msg.width, m.msg.height, m.msg.step = w, h, w
            m.msg.data = np.full(w * h, 40, dtype=np.uint8)
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "frames.mcap", fault)
    s = run_summary(tiny, log, tmp_path / "est")
    assert pick.hits > 5
    clean = tiny.run["warnings"].get("bad_frames", 0)
    assert s["warnings"]["bad_frames"] == clean + pick.hits
    assert s["counts"]["frames"] == tiny.run["counts"]["frames"] - pick.hits


def test_implausible_sonar_readings_are_counted(tiny, tmp_path: Path) -> None:
    """Readings whose max_range is 1e30 m or field of view 1e10 rad: counted
    (implausible, bad_fov), never used; the map's masses stay valid."""
    far = Every(SONAR, 9)
    wide = Every(SONAR, 11)

    def fault(m: LogMessage) -> list[Out]:
        if far(m):
            m.msg.max_range = 1e30
        if wide(m):
            m.msg.field_of_view = 1e10
        return keep(m)

    log = rewrite(tiny.log, tmp_path / "sonar.mcap", fault)
    s = map_json(tiny, log, tmp_path / "fgm")["sonar_stats"]
    clean = tiny.map["sonar_stats"]
    assert far.hits > 20 and wide.hits > 20
    assert s["implausible"] == far.hits
    assert s["bad_fov"] == clean["bad_fov"] + wide.hits
    assert s["readings"] == clean["readings"]


@pytest.mark.parametrize("which", ["first", "middle"])
def test_map_reports_a_corrupt_chunk(tiny, tmp_path: Path, which: str) -> None:
    """A chunk with 8 flipped bytes: map runs on the rest and its summary says what was
    lost (log_damage), with fewer rings than the clean log (not silently missing)."""
    import shutil

    from mcap.reader import make_reader

    with open(tiny.log, "rb") as f:
        chunks = sorted(
            (c.chunk_start_offset, c.chunk_length)
            for c in make_reader(f).get_summary().chunk_indexes
        )
    assert len(chunks) >= 3
    start, length = chunks[0] if which == "first" else chunks[len(chunks) // 2]
    log = tmp_path / "corrupt.mcap"
    shutil.copyfile(tiny.log, log)
    with open(log, "r+b") as f:
        f.seek(start + length // 2)
        raw = f.read(8)
        f.seek(start + length // 2)
        f.write(bytes(b ^ 0xFF for b in raw))
    s = map_json(tiny, log, tmp_path / "fgm")
    assert s["log_damage"]["damaged_records"] >= 1 and s["log_damage"]["lost_bytes"] > 0
    assert s["sonar_stats"]["rings"] < tiny.map["sonar_stats"]["rings"]
