"""The odometry's turns against the estimate's (slam/turn_check.py): a turn scale that
the innovations hide is flagged in filter_health, never on runs whose odometry is right."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli

from fuzzyslam.slam import turn_check as tc
from fuzzyslam.slam.turn_check import rotation_factor, turn_note, turn_ratio

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"


def _drive(k: float, seconds: float = 900.0, noise: float = 0.02, seed: int = 0):
    """A robot turning at random (0.05 s samples): the odometry's heading, and the
    estimate's = k times it plus a random walk of ``noise`` rad per sqrt(window)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 0.05)
    rate = np.repeat(rng.normal(0.0, 0.3, len(t) // 100 + 1), 100)[: len(t)]
    yaw_odo = np.cumsum(rate) * 0.05
    walk = np.cumsum(rng.normal(0.0, noise * math.sqrt(0.05 / tc.WINDOW_S), len(t)))
    return t, k * yaw_odo + walk, yaw_odo


@pytest.mark.parametrize("k", [0.8, 0.97, 1.0, 1.25])
def test_the_ratio_of_turns_is_recovered_within_its_error(k) -> None:
    t, est, odo = _drive(k)
    c = turn_ratio(t, est, odo)
    assert c is not None and c.windows >= 28
    assert abs(c.ratio - k) < 3 * c.sd and c.sd < 0.01
    assert c.flagged == (abs(k - 1) > tc.TOLERANCE)
    # wrapped headings give the same answer
    w = turn_ratio(t, np.angle(np.exp(1j * est)), np.angle(np.exp(1j * odo)))
    assert w.ratio == pytest.approx(c.ratio, rel=1e-9)


def test_a_relocalisation_jump_is_left_out() -> None:
    """A 1-rad correction in one window (a relocalisation, a pose fix) moves the ratio
    by less than its error: the window is beyond three robust sigmas."""
    t, est, odo = _drive(1.0)
    jumped = est + np.where(t > 400.0, 1.0, 0.0)
    a, b = turn_ratio(t, est, odo), turn_ratio(t, jumped, odo)
    assert b.windows == a.windows - 1
    assert abs(b.ratio - a.ratio) < a.sd and not b.flagged


def test_too_little_turning_or_too_short_gives_no_ratio() -> None:
    t = np.arange(0.0, 900.0, 0.05)
    straight = 0.001 * np.sin(t / 50.0)  # 0.1 deg of wobble: no turning to compare
    assert turn_ratio(t, straight, straight) is None
    t, est, odo = _drive(0.8, seconds=tc.WINDOW_S * (tc.MIN_WINDOWS - 1))
    assert turn_ratio(t, est, odo) is None


def test_flagged_from_the_first_window_the_test_holds_on() -> None:
    """Right odometry for 450 s, then its turns 30 % long: flagged, from a window after
    the change; the prefix tests (running sums) equal the fits on each prefix."""
    t, est, odo = _drive(1.0)
    late = t > 450.0
    odo2 = odo.copy()
    odo2[late] = odo[late][0] + (odo[late] - odo[late][0]) * 1.3
    c = turn_ratio(t, est, odo2)
    assert c.flagged and c.ratio < 0.9
    assert c.flagged_at > 450.0
    edges = np.arange(t[0], t[-1] + 1e-9, tc.WINDOW_S)
    e = np.diff(np.interp(edges, t, est))
    o = np.diff(np.interp(edges, t, odo2))
    # the second implementation: each prefix fitted on its own (no window is trimmed here)
    held = [tc._flagged(*tc._fit(e[:j], o[:j]), 1.0) for j in range(tc.MIN_WINDOWS, len(o) + 1)]
    first = max(j for j, h in enumerate(held) if not h) + 1
    assert c.flagged_at == pytest.approx(edges[tc.MIN_WINDOWS + first])


def test_rotation_factor_of_the_calibration_models() -> None:
    """Wheels: a spin on the spot with nominal wheel angles a_R = -a_L turns
    (s_R a_R - s_L a_L) / (b s_B) (slam/calibration.py) = (s_L + s_R) / 2 / s_B times
    the nominal turn; Odometry: the rotation scale; none: 1."""
    s_l, s_r, s_b = 1.01, 0.99, 1.25
    a, b = 0.3, 0.4
    nominal = (a - -a) / b
    true = (s_r * a - s_l * -a) / (b * s_b)
    names = ["left_scale", "right_scale", "base_scale"]
    assert rotation_factor(names, [s_l, s_r, s_b]) == pytest.approx(true / nominal)
    assert rotation_factor(["trans_scale", "rot_scale"], [0.97, 1.12]) == 1.12
    assert rotation_factor([], []) == 1.0


def test_the_note_says_which_way_and_against_what() -> None:
    line = turn_note({"ratio": 0.796, "sd": 0.003, "windows": 12, "expected": 1.0})
    assert "20 % less than the odometry over 12 windows" in line
    assert "slam.calibrate: true learns it" in line
    line = turn_note({"ratio": 0.95, "sd": 0.003, "windows": 12, "expected": 0.8})
    assert "19 % more than the odometry as calibrated (0.800)" in line


def _world(tmp: Path, base_scale: float, calibrate: bool) -> Path:
    cfg = tmp / f"base{base_scale}_{calibrate}.yaml"
    cfg.write_text(
        "extends: quick.yaml\nname: turns\nscenario:\n  runs: 3\n"
        f"robot:\n  base_scale: {base_scale}\nslam:\n  calibrate: {str(calibrate).lower()}\n"
    )
    return cfg


@pytest.mark.slow
def test_a_wrong_wheel_base_is_flagged_unless_calibrated(tmp_path, capsys) -> None:
    """The simulator's true wheel base 25 % longer than the robot's (6 min, 1460 deg of
    turning): the lamps keep the estimate's heading true and the innovations' tests
    quiet, and the estimate turns 0.80 times the odometry. Flagged (reason
    odometry_turn_scale, one line naming the ratio) with the calibration off; with it
    on, the learnt base (1.25) explains the ratio and nothing is flagged; the same world
    with the right base flags nothing."""
    wrong = _world(tmp_path, 1.25, False)
    log = tmp_path / "wrong.mcap"
    code, _, err = run_cli(["simulate", str(wrong), "-o", str(log), "--seed", "1"], capsys)
    assert code == 0, err
    code, s, err = run_cli(
        ["run", str(log), "--config", str(wrong), "-o", str(tmp_path / "a")], capsys
    )
    assert code == 0, err
    check = s["odometry_turn_check"]
    assert check["flagged"] and check["ratio"] == pytest.approx(0.8, abs=0.01)
    assert s["filter_health"]["diverged"]
    # the only reason: the innovations' windows did not flag it
    assert s["filter_health"]["reasons"] == ["odometry_turn_scale"]
    lines = [x for x in err.splitlines() if "odometry_turn_check" in x]
    assert len(lines) == 1 and "20 % less than the odometry" in lines[0]
    calibrated = _world(tmp_path, 1.25, True)
    code, s, err = run_cli(
        ["run", str(log), "--config", str(calibrated), "-o", str(tmp_path / "b")], capsys
    )
    assert code == 0, err
    assert s["calibration"]["factors"][2] == pytest.approx(1.25, abs=0.02)
    assert not s["odometry_turn_check"]["flagged"] and not s["filter_health"]["diverged"]
    assert s["odometry_turn_check"]["expected"] == pytest.approx(0.8, abs=0.02)
    right = _world(tmp_path, 1.01, False)
    log = tmp_path / "right.mcap"
    assert run_cli(["simulate", str(right), "-o", str(log), "--seed", "1"], capsys)[0] == 0
    code, s, err = run_cli(
        ["run", str(log), "--config", str(right), "-o", str(tmp_path / "c")], capsys
    )
    assert code == 0, err
    assert not s["odometry_turn_check"]["flagged"] and not s["filter_health"]["diverged"]
    assert s["odometry_turn_check"]["ratio"] == pytest.approx(1 / 1.01, abs=0.01)


def _scale_turns(src: Path, dst: Path, scale: float) -> None:
    """The log with its /odom poses integrated again from their increments, each turn
    times ``scale`` (a driver with a wrong angular scale)."""
    from fuzzyslam.streams.reader import LogReader
    from fuzzyslam.streams.writer import LogWriter

    reader = LogReader(src)
    prev = cur = None
    with LogWriter(dst) as w:
        for name in sorted(reader.metadata):
            w.metadata(name, reader.metadata[name])
        for m in reader.messages():
            msg = m.msg
            if m.topic == "/odom":
                p, q = msg.pose.pose.position, msg.pose.pose.orientation
                pose = (p.x, p.y, 2.0 * math.atan2(q.z, q.w))
                if prev is None:
                    cur = pose
                else:
                    dx, dy = pose[0] - prev[0], pose[1] - prev[1]
                    c, s = math.cos(prev[2]), math.sin(prev[2])
                    bx, by = c * dx + s * dy, -s * dx + c * dy
                    dth = math.remainder(pose[2] - prev[2], math.tau) * scale
                    c, s = math.cos(cur[2]), math.sin(cur[2])
                    cur = (cur[0] + c * bx - s * by, cur[1] + s * bx + c * by, cur[2] + dth)
                prev = pose
                p.x, p.y = cur[0], cur[1]
                q.x = q.y = 0.0
                q.z, q.w = math.sin(cur[2] / 2), math.cos(cur[2] / 2)
                msg.twist.twist.angular.z *= scale
            w.write(m.topic, m.typename, msg, m.t)


@pytest.mark.slow
def test_a_real_log_with_its_turns_scaled_is_flagged(tmp_path, capsys) -> None:
    """MRCLAM robot 3 (whole log, ../shared) with its odometry's turns times 0.8: NEES
    1050 against 5.6 as recorded, every NIS and association window in bounds; flagged,
    the estimate turning at least 10 % more than the odometry. The log as recorded flags
    nothing (tests/test_real_landmarks_full.py)."""
    log = REAL / "mrclam7-robot3" / "log.mcap"
    if not log.is_file():
        pytest.skip(f"{log} not here (the shared real logs)")
    scaled = tmp_path / "scaled.mcap"
    _scale_turns(log, scaled, 0.8)
    args = ["run", str(scaled), "--config", "real_detections", "-o", str(tmp_path / "r")]
    code, s, err = run_cli(args, capsys)
    assert code == 0, err
    assert s["odometry_turn_check"]["flagged"] and s["odometry_turn_check"]["ratio"] > 1.1
    assert "odometry_turn_scale" in s["filter_health"]["reasons"]
    assert s["filter_health"]["nis_windows_out_of_bounds"] == 0
