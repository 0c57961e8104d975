"""How a range sensor's near readings are read (streams/scan.py ``scan_ranges``,
streams/sonar.py ``group_rings``): a LaserScan's exact 0.0 below range_min as no echo
or invalid (``ranges.scan_zero``), echoes nearer than ``ranges.min_range_m`` invalid
(the robot's own body), and a note with the counts when most readings are invalid
(``invalid_ranges`` in the run's and map's summaries)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import run_cli

from fuzzyslam.config import load_config
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.ranges import invalid_note, invalid_ranges, open_ranges
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.scan import scan_geometry, scan_ranges, scan_rings
from fuzzyslam.streams.sonar import RingStats, group_rings
from fuzzyslam.streams.writer import LogWriter

TF = "tf2_msgs/msg/TFMessage"
BEAMS = 360  # an LDS-01: 1-deg beams all round, range 0.12-3.5 m, 0.0 for no return
SCANS = 8


def _counts(got) -> tuple[int, ...]:
    return got.invalid, got.no_echo, got.zeros, got.zeros_invalid, got.too_near


def test_exact_zero_is_no_echo_by_default_or_invalid_when_set():
    """An LDS-01's 0.0 below range_min 0.12: no echo (range_max, counted in
    ``no_echo`` and ``zeros``) by default; invalid (NaN) with ``invalid``. A tiny
    positive range below range_min and -inf stay invalid either way; 0.0 is an echo
    only where the message's range_min (and min_range) admit it."""
    raw = np.array([1.5, 0.0, 0.01, -np.inf, np.inf, 0.0], dtype=np.float32)
    got = scan_ranges(raw, 0.12, 3.5)
    np.testing.assert_allclose(got.ranges[[0, 1, 4, 5]], [1.5, 3.5, 3.5, 3.5], rtol=1e-6)
    assert np.isnan(got.ranges[[2, 3]]).all() and _counts(got) == (2, 3, 2, 0, 0)
    got = scan_ranges(raw, 0.12, 3.5, "invalid")
    assert np.isnan(got.ranges[[1, 2, 3, 5]]).all() and got.ranges[4] == 3.5
    assert _counts(got) == (4, 1, 2, 2, 0)
    got = scan_ranges(raw, 0.0, 3.5, "invalid")  # range_min 0: 0.0 is an echo
    assert got.ranges[1] == 0.0 and got.zeros == 0 and got.invalid == 1
    got = scan_ranges(raw, 0.0, 3.5, "no_echo", 0.1)  # below min_range: not an echo
    assert got.ranges[1] == 3.5 and _counts(got) == (2, 3, 2, 0, 1)  # 0.01: too near
    with pytest.raises(ValueError, match="no_echo"):
        scan_ranges(raw, 0.12, 3.5, "zero")


def test_zero_is_no_echo_only_on_a_beam_that_has_echoed():
    """A beam that reads 0.0 in every scan (blocked by the robot's own body, or outside
    the laser's real view) is no open space: its 0.0 is invalid until it has echoed once
    (``scan_rings`` remembers which beams have); a 0.0 on a beam that has is no echo."""
    a_min, a_inc = -math.pi, 2 * math.pi / 8
    scans = [[1.0, 0.0, 2.0, 0.0, 1.0, 1.0, 1.0, 1.0], [0.0, 0.0, 0.0, 1.5, 1.0, 1.0, 1.0, 1.0]]
    msgs = [
        SimpleNamespace(
            topic="/scan", msg=M.laser_scan(1.0 + k, "laser", np.array(r), a_min, a_inc, 0.12, 3.5)
        )
        for k, r in enumerate(scans)
    ]
    st = RingStats()
    first, second = scan_rings(msgs, scan_geometry(msgs[0].msg), math.radians(45.0), st)
    assert np.isnan(first.ranges[[1, 3]]).all()  # never echoed yet
    assert list(second.ranges[:4]) == [3.5, pytest.approx(np.nan, nan_ok=True), 3.5, 1.5]
    assert st.zero_ranges == 5 and st.zero_invalid == 3 and st.no_echo == 2 and st.invalid == 3
    echoed = np.array([True, False, True])
    got = scan_ranges(np.zeros(3, dtype=np.float32), 0.12, 3.5, echoed=echoed)
    np.testing.assert_array_equal(np.isnan(got.ranges), ~echoed)
    assert got.zeros_invalid == 1 and got.no_echo == 2


def test_min_range_drops_echoes_off_the_robot_body():
    """Echoes nearer than ``min_range_m`` (0.15-0.2 m off the robot's struts, above
    range_min) are invalid and counted ``too_near``, not walls; farther ones and no
    echoes are kept. Sonar Range messages follow the same rule."""
    raw = np.array([0.15, 0.19, 0.26, 2.0, 0.0, 3.5], dtype=np.float32)
    got = scan_ranges(raw, 0.12, 3.5, min_range=0.25)
    assert np.isnan(got.ranges[:2]).all() and _counts(got) == (2, 2, 1, 0, 2)
    np.testing.assert_allclose(got.ranges[2:], [0.26, 2.0, 3.5, 3.5], rtol=1e-6)
    got = scan_ranges(raw, 0.12, 3.5)  # without it: walls on the robot
    assert np.isfinite(got.ranges).all() and got.invalid == 0
    fov = math.radians(25.0)
    msgs = [
        SimpleNamespace(topic=f"/sonar/s0{i}", msg=M.range_msg(1.0, f"s{i}", rr, fov, 0.1, 5.0))
        for i, rr in enumerate([0.18, 0.3, 5.0])
    ]
    topics = {m.topic: i for i, m in enumerate(msgs)}
    st = RingStats()
    (ring,) = group_rings(msgs, topics, 3, stats=st, min_range=0.25)
    assert np.isnan(ring.ranges[0]) and ring.ranges[1] == pytest.approx(0.3)
    assert st.invalid == st.too_near == 1 and st.no_echo == 1
    (ring,) = group_rings(msgs, topics, 3)
    assert ring.ranges[0] == pytest.approx(0.18)


def _lds_log(path: Path, seen: bool = True) -> Path:
    """A TurtleBot-like log: the robot still at the origin, a wall 1.5 m ahead seen by
    the beams within 60 deg of the laser's axis, every other beam no return (0.0); with
    ``seen``, the first scan sees walls all round (every beam has echoed)."""
    a = -math.pi + np.arange(BEAMS) * (2 * math.pi / BEAMS)
    raw = np.where(np.abs(a) < math.radians(59.5), 1.5 / np.cos(a), 0.0)
    mount = M.transform_stamped(0.0, "base_link", "laser", 0.0, 0.0, 0.2, 0.0)
    with LogWriter(path) as w:
        w.write("/tf_static", TF, M.tf_message([mount]), 0.0)
        for k in range(10 * SCANS):
            t = 1.0 + 0.1 * k
            w.write("/odom", M.ODOMETRY, M.odometry(t, "odom", "base_link", np.zeros(3)), t)
            if k % 10 == 5:
                r = np.where(raw > 0, raw, 2.0) if seen and k == 5 else raw
                scan = M.laser_scan(t, "laser", r, -math.pi, 2 * math.pi / BEAMS, 0.12, 3.5)
                w.write("/scan", M.LASER_SCAN, scan, t)
    return path


def _expected(step: int) -> tuple[int, int]:
    """(kept beams read, of them 0.0 after the first scan) over the log's scans."""
    a = np.degrees(-math.pi + np.arange(0, BEAMS, step) * (2 * math.pi / BEAMS))
    return SCANS * len(a), (SCANS - 1) * int(np.count_nonzero(np.abs(a) >= 59.5))


def test_many_zeros_read_as_invalid_are_said_with_their_counts(tmp_path, capsys):
    """``map`` and ``run`` on an LDS log: by default the 0.0 are no echoes and nothing is
    said; with ``scan_zero: invalid`` most beams are invalid, and a note on stderr and
    ``invalid_ranges`` in the summaries give the counts, the cause and the setting. Beams
    that never echo (the robot's body): invalid by default too, and said so."""
    log = _lds_log(tmp_path / "lds.mcap")
    traj = tmp_path / "traj.tum"
    traj.write_text("".join(f"{1.0 + 0.1 * k:.1f} 0 0 0 0 0 0 1\n" for k in range(10 * SCANS)))
    strict = tmp_path / "strict.yaml"
    strict.write_text("extends: real_building_scan\nranges:\n  scan_zero: invalid\n")
    cfg = load_config("real_building_scan.yaml")
    readings, zeros = _expected(open_ranges(LogReader(log), cfg, "scan").geometry.step)
    assert zeros > readings / 2
    args = ["map", str(log), "--trajectory", str(traj), "--ranges", "scan", "-o"]
    code, s, err = run_cli([*args, str(tmp_path / "a"), "--config", "real_building_scan"], capsys)
    assert code == 0, err
    st = s["sonar_stats"]
    assert st["readings"] == readings and st["zero_ranges"] == zeros and st["invalid"] == 0
    assert st["no_echo"] == zeros and "invalid_ranges" not in s and "invalid" not in err
    assert s["range_sensor"]["scan_zero"] == "no_echo"
    code, s, err = run_cli([*args, str(tmp_path / "b"), "--config", str(strict)], capsys)
    assert code == 0, err
    found = s["invalid_ranges"]
    assert found["readings"] == readings and found["invalid"] == found["zero_invalid"] == zeros
    assert found["other"] == found["too_near"] == 0 and found["scan_zero"] == "invalid"
    line = f"{zeros} of {readings} range readings ({100 * zeros / readings:.0f} %) are invalid"
    assert line in err and "ranges.scan_zero: invalid; no_echo reads them as no return" in err
    run = ["run", str(log), "--live-map", "-o"]
    code, s, err = run_cli([*run, str(tmp_path / "r"), "--config", str(strict)], capsys)
    assert code == 0, err
    assert s["invalid_ranges"] == found and line in err
    code, s, err = run_cli([*run, str(tmp_path / "r0"), "--config", "real_building_scan"], capsys)
    assert code == 0, err
    assert "invalid_ranges" not in s and s["rings"]["zero_ranges"] == zeros
    assert "are invalid" not in err
    blocked = _lds_log(tmp_path / "blocked.mcap", seen=False)
    code, s, err = run_cli(
        ["map", str(blocked), *args[2:], str(tmp_path / "c"), "--config", "real_building_scan"],
        capsys,
    )
    assert code == 0, err
    n = zeros * SCANS // (SCANS - 1)  # the first scan's rear too
    assert s["invalid_ranges"]["zero_invalid"] == s["sonar_stats"]["zero_invalid"] == n
    assert f"{n} exact 0.0 on beams that had never echoed" in err


def test_the_note_names_the_commonest_cause_first():
    """NaN beams and echoes dropped by ``min_range_m``: the larger count first, each with
    what to check. At most a third invalid, not counting the echoes ``min_range_m``
    drops (the config's choice), says nothing."""
    sensor = SimpleNamespace(kind="scan", topics=["/scan"], zero="no_echo", min_range=0.3)
    st = RingStats(readings=90, invalid=50, too_near=10, zero_ranges=12)
    found = invalid_ranges(st, sensor)
    assert found["zero_invalid"] == 0 and found["too_near"] == 10 and found["other"] == 40
    line = invalid_note(found)
    assert line.startswith("/scan: 50 of 90 range readings (56 %)")
    assert line.index("40 NaN, -inf") < line.index("10 echoes nearer than ranges.min_range_m")
    assert invalid_ranges(replace(st, invalid=40), sensor) is None
