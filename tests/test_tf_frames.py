"""/tf in estimates.mcap follows the log's own frames (issue 17): the odometry's frame
names (nav_msgs/Odometry header.frame_id, child_frame_id), and no second odom -> base
when the log's /tf already carries it, so the sensor log and the estimates open as one
tree. Checked on copies of the committed real excerpt (data/real/mrclam6_excerpt) whose
/odom is renamed and, for one, also published on /tf."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fuzzyslam.se2 import compose, interpolate_poses
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.writer import LogWriter

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "real" / "mrclam6_excerpt" / "log.mcap"


def _rewrite(dst: Path, odom: str, base: str, with_tf: bool) -> None:
    with LogWriter(dst) as w:
        for m in LogReader(EXCERPT).messages():
            if m.topic == "/odom":
                m.msg.header.frame_id, m.msg.child_frame_id = odom, base
                if with_tf:
                    t = M.stamp_to_sec(m.msg.header.stamp)
                    x, y, yaw = M.pose_of(m.msg.pose.pose)
                    ts = M.transform_stamped(t, odom, base, x, y, 0.0, yaw)
                    w.write("/tf", M.TF_MESSAGE, M.tf_message([ts]), m.t)
            w.write(m.topic, m.typename, m.msg, m.t)


def _run(log: Path, out: Path) -> None:
    r = subprocess.run(
        [sys.executable, "-m", "fuzzyslam", "run", str(log), "--config",
         "real_detections.yaml", "-o", str(out)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr


def _tf_pairs(out: Path) -> tuple[set[tuple[str, str]], list, list]:
    pairs, tf, poses = set(), [], []
    for m in LogReader(out / "estimates.mcap").messages(["/tf", "/slam/pose"]):
        if m.topic == "/tf":
            for ts in m.msg.transforms:
                pairs.add((ts.header.frame_id, ts.child_frame_id))
            tf.append((M.stamp_to_sec(m.msg.transforms[0].header.stamp),
                       M.planar_transforms(m.msg)))  # fmt: skip
        else:
            poses.append(M.pose_of(m.msg.pose.pose))
    return pairs, tf, poses


@pytest.mark.slow
def test_frames_follow_the_log(tmp_path: Path) -> None:
    """Renamed odometry frames: /tf is map -> wheel_odom -> chassis and composes to
    /slam/pose; with the log's own /tf carrying wheel_odom -> chassis, estimates.mcap
    holds map -> wheel_odom only, and that correction composed with the log's odometry
    (its /tf at the pose's stamp) is the estimate."""
    renamed = tmp_path / "renamed.mcap"
    _rewrite(renamed, "wheel_odom", "chassis", with_tf=False)
    _run(renamed, tmp_path / "a")
    pairs, tf, poses = _tf_pairs(tmp_path / "a")
    assert pairs == {("map", "wheel_odom"), ("wheel_odom", "chassis")}
    k = len(tf) // 2
    got = compose(tf[k][1]["wheel_odom"][1], tf[k][1]["chassis"][1])
    assert np.allclose(got, poses[k], atol=1e-9)

    own = tmp_path / "own_tf.mcap"
    _rewrite(own, "wheel_odom", "chassis", with_tf=True)
    _run(own, tmp_path / "b")
    pairs_b, tf_b, poses_b = _tf_pairs(tmp_path / "b")
    assert pairs_b == {("map", "wheel_odom")}
    # the filter did not change; its correction is against the log's own odom -> chassis
    # at each pose's stamp (interpolated between the log's /tf stamps; REP 105), not
    # against the run's dead reckoning, which starts at the first plausible /odom pose
    assert len(tf_b) == len(tf)
    assert np.array_equal(poses_b, poses)
    lt, lp = _log_odom(own)
    stamps = np.array([s for s, _ in tf_b])
    odom = interpolate_poses(lt, lp, stamps, outside="hold")
    corr = np.array([m["wheel_odom"][1] for _, m in tf_b])
    assert np.allclose(compose(corr, odom), poses_b, atol=1e-9)


def _log_odom(log: Path) -> tuple[np.ndarray, np.ndarray]:
    """The log's /tf wheel_odom -> chassis: stamps and poses."""
    t, p = [], []
    for m in LogReader(log).messages(["/tf"]):
        t.append(M.stamp_to_sec(m.msg.transforms[0].header.stamp))
        p.append(M.planar_transforms(m.msg)["chassis"][1])
    return np.asarray(t), np.asarray(p)
