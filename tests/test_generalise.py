"""benchmarks/generalise.py: the re-synthesised odometry of "other logs of the same kind"
(analytic paths with known errors) and its copy of a log (every other topic unchanged),
and the windows cut from a landmark log."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from generalise import OdomErrors, cut_window, resynthesise, synthetic_odometry

from fuzzyslam.se2 import quaternion_to_yaw, wrap_angle
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.typestore import serialize
from fuzzyslam.streams.writer import LogWriter

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "real" / "mrclam6_excerpt"
NONE = OdomErrors(0.0, 0.0, 0.0, 0.0, 0.0, seed=0)


def _loop(n: int = 400) -> np.ndarray:
    """A drive: 5 m straight, a quarter circle of radius 1 m, 3 m straight (n poses)."""
    s = np.linspace(0.0, 5.0 + math.pi / 2 + 3.0, n)
    x = np.where(s < 5, s, np.where(s < 5 + math.pi / 2, 5 + np.sin(s - 5), 6.0))
    y = np.where(
        s < 5, 0.0, np.where(s < 5 + math.pi / 2, 1 - np.cos(s - 5), 1 + s - 5 - math.pi / 2)
    )
    th = np.clip(s - 5, 0.0, math.pi / 2)
    return np.column_stack([x + 2.0, y - 1.0, th + 0.3])


def _rotate(p: np.ndarray, a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.column_stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1], p[:, 2] + a])


def test_no_errors_is_the_truth():
    truth = _rotate(_loop(), 0.7)
    odo = synthetic_odometry(truth, NONE)
    np.testing.assert_allclose(odo[:, :2], truth[:, :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(odo[:, 2] - truth[:, 2]), 0.0, atol=1e-12)


def test_scale_and_bias_are_what_they_say():
    """Translation scale s: every step (1 + s) as long; rotation scale r: the quarter
    turn (1 + r) pi / 2; heading bias b: b rad per metre driven, here 8 + pi / 2 m."""
    truth = _loop()
    odo = synthetic_odometry(truth, OdomErrors(0.03, 0.0, 0.0, 0.0, 0.0))
    steps = np.hypot(*np.diff(odo[:, :2], axis=0).T)
    np.testing.assert_allclose(steps, 1.03 * np.hypot(*np.diff(truth[:, :2], axis=0).T))
    odo = synthetic_odometry(truth, OdomErrors(0.0, -0.02, 0.0, 0.0, 0.0))
    assert math.isclose(odo[-1, 2] - odo[0, 2], 0.98 * math.pi / 2, rel_tol=1e-9)
    length = np.hypot(*np.diff(truth[:, :2], axis=0).T).sum()
    odo = synthetic_odometry(truth, OdomErrors(0.0, 0.0, 0.0, 0.0, 0.5))
    turned = odo[-1, 2] - odo[0, 2] - math.pi / 2
    assert math.isclose(turned, math.radians(0.5) * length, rel_tol=1e-9)


def test_random_errors_scale_with_the_step():
    """2 % of each step's distance at random: the ratio of odometry to true step length
    has a standard deviation of 0.02 (a second draw: another path)."""
    truth = _loop(20000)
    e = OdomErrors(0.0, 0.0, 0.02, 0.0, 0.0, seed=3)
    odo = synthetic_odometry(truth, e)
    ratio = np.hypot(*np.diff(odo[:, :2], axis=0).T) / np.hypot(*np.diff(truth[:, :2], axis=0).T)
    assert abs(ratio.std() - 0.02) < 0.001
    other = synthetic_odometry(truth, OdomErrors(0.0, 0.0, 0.02, 0.0, 0.0, seed=4))
    assert not np.allclose(other, odo)


def test_resynthesised_log_copies_every_other_topic(tmp_path):
    """A log whose /odom repeats /ground_truth/odom: with no errors the new /odom is the
    truth; every other message is the same bytes at the same time."""
    src = tmp_path / "src.mcap"
    reader = LogReader(EXCERPT / "log.mcap")
    with LogWriter(src) as w:
        for m in reader.messages(["/ground_truth/odom", "/landmark_detections"]):
            data = serialize(m.msg, m.typename)
            w.write_cdr(m.topic, m.typename, data, m.t)
            if m.topic == "/ground_truth/odom":
                w.write_cdr("/odom", m.typename, data, m.t)
    out = tmp_path / "out.mcap"
    resynthesise(src, out, OdomErrors(0.01, -0.005, 0.0, 0.0, 0.05))
    a, b = LogReader(src), LogReader(out)
    for topic in ("/ground_truth/odom", "/landmark_detections"):
        ma, mb = list(a.messages([topic])), list(b.messages([topic]))
        assert [m.t_ns for m in ma] == [m.t_ns for m in mb]
        assert all(
            serialize(x.msg, x.typename) == serialize(y.msg, y.typename)
            for x, y in zip(ma, mb, strict=True)
        )
    odo = [m.msg.pose.pose for m in b.messages(["/odom"])]
    gt = [m.msg.pose.pose for m in a.messages(["/ground_truth/odom"])]
    assert len(odo) == len(gt)
    # the first pose is the truth's; the heading then drifts by the bias over the distance
    assert (odo[0].position.x, odo[0].position.y) == (gt[0].position.x, gt[0].position.y)
    yaw = lambda p: quaternion_to_yaw([p.orientation.x, p.orientation.y, p.orientation.z,  # noqa: E731
                                       p.orientation.w])  # fmt: skip
    assert abs(yaw(odo[-1]) - yaw(gt[-1])) > 1e-4
    resynthesise(src, tmp_path / "none.mcap", NONE)
    odo = [m.msg.pose.pose for m in LogReader(tmp_path / "none.mcap").messages(["/odom"])]
    np.testing.assert_allclose([p.position.x for p in odo], [p.position.x for p in gt], atol=1e-9)


def test_window_keeps_its_span(tmp_path):
    """A window of a landmark log: its messages and truth rows lie within it."""
    cut_window(EXCERPT, tmp_path / "w", 30.0, 40.0)
    reader = LogReader(EXCERPT / "log.mcap")
    r = LogReader(tmp_path / "w" / "log.mcap")
    assert reader.start + 30.0 <= r.start and r.end <= reader.start + 70.0
    rows = [ln for ln in (tmp_path / "w" / "truth.tum").read_text().splitlines() if ln[0] != "#"]
    t = np.array([float(ln.split()[0]) for ln in rows])
    assert len(t) and t.min() >= reader.start + 30.0 and t.max() <= reader.start + 70.0
