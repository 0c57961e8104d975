"""Variants of a recorded log, as other robots would record it, for the benchmarks.

Run: python benchmarks/log_variants.py SRC DST [--sonar-sequential DT] [--odometry-every N]

- ``--sonar-sequential DT``: the sonar ring stamped as a Pioneer's is: sonar k of each
  ring (k-th in topic order) stamped and logged DT seconds after sonar k-1 (simulated
  and CARMEN logs stamp a whole ring alike). The ranges stay those of the original
  instant, so this is a sonar whose stamps are k * DT late, not a ring fired in
  sequence from a moving robot: it tests the grouping of readings into rings; the
  placement of readings fired in sequence is tested on the simulator's
  (``sonar.firing_gap_s``), where each reading is taken at its stamp.
- ``--odometry-every N``: odometry at 1/N of its rate (every N-th /odom message kept).
- ``--detections-yaw DEG``: the landmark detections (PoseArray on
  /landmark_detections, base_link) turned by DEG about the robot: a detector whose
  mount yaw is off by that much.
- ``--odometry-scale D,T``: the /odom poses integrated again from their increments, each
  translation (in the previous pose's frame) times D and each turn times T, the twist
  alike: a driver with a wrong linear or angular scale (a wheel radius, a wheel base).
  The README's figures for the turn and distance checks of filter_health come from
  these variants of the MRCLAM logs, e.g.::

      python benchmarks/log_variants.py ../shared/data/real/mrclam7-robot3 \\
          /tmp/v/mrclam7-robot3 --odometry-scale 1.25,1
      python benchmarks/bench_real_landmarks.py /tmp/v

SRC and DST are directories holding ``log.mcap`` (and ``truth.tum`` and
``landmarks_truth.yaml``, linked into DST), so
that ``bench_buildings.py --data`` reads DST's parent as it reads the real logs. The
README's figures for restamped sonars and slow odometry come from these variants of
the CARMEN logs, e.g.::

    python benchmarks/log_variants.py ../shared/data/real/carmen-aces /tmp/v/carmen-aces \\
        --odometry-every 5
    python benchmarks/bench_buildings.py --data /tmp/v
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.writer import LogWriter


class OdometryScale:
    """/odom poses integrated again from their increments, each translation (in the
    previous pose's frame) times ``distance`` and each turn times ``turn``."""

    def __init__(self, distance: float, turn: float) -> None:
        self.distance, self.turn = distance, turn
        self.prev: tuple[float, float, float] | None = None
        self.cur: tuple[float, float, float] | None = None

    def __call__(self, msg) -> None:
        """Rewrite one nav_msgs/Odometry in place."""
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        pose = (p.x, p.y, 2.0 * math.atan2(q.z, q.w))
        cur = pose if self.cur is None else self.cur
        if self.prev is not None:
            dx, dy = pose[0] - self.prev[0], pose[1] - self.prev[1]
            c, s = math.cos(self.prev[2]), math.sin(self.prev[2])
            bx, by = self.distance * (c * dx + s * dy), self.distance * (-s * dx + c * dy)
            dth = math.remainder(pose[2] - self.prev[2], math.tau) * self.turn
            c, s = math.cos(cur[2]), math.sin(cur[2])
            cur = (cur[0] + c * bx - s * by, cur[1] + s * bx + c * by, cur[2] + dth)
        self.prev, self.cur = pose, cur
        p.x, p.y = cur[0], cur[1]
        q.x = q.y = 0.0
        q.z, q.w = math.sin(cur[2] / 2), math.cos(cur[2] / 2)
        msg.twist.twist.linear.x *= self.distance
        msg.twist.twist.angular.z *= self.turn


def write_variant(
    src: Path,
    dst: Path,
    sonar_dt: float = 0.0,
    odometry_every: int = 1,
    odometry_scale: tuple[float, float] = (1.0, 1.0),
    detections_yaw_deg: float = 0.0,
) -> None:
    """Copy the log ``src`` to ``dst`` message by message (metadata first), changed as the
    options say (module docstring).

    Parameters
    ----------
    src, dst : Path
        The MCAP files.
    sonar_dt : float
        Step between the sonars of a ring (s); 0: unchanged.
    odometry_every : int
        Keep every N-th /odom message (1: all).
    odometry_scale : (float, float)
        The /odom translations' and turns' factors (:class:`OdometryScale`).
    detections_yaw_deg : float
        The detections' turn about the robot (deg); 0: unchanged.
    """
    reader = LogReader(src)
    order = {
        tp: k for k, tp in enumerate(sorted(t for t in reader.topics if t.startswith("/sonar/s")))
    }
    seen = 0
    scale = OdometryScale(*odometry_scale) if tuple(odometry_scale) != (1.0, 1.0) else None
    with LogWriter(dst) as w:
        for name in sorted(reader.metadata):
            w.metadata(name, reader.metadata[name])
        for m in reader.messages():
            t = m.t
            if m.topic == "/odom":
                seen += 1
                if (seen - 1) % odometry_every:
                    continue
                if scale is not None:
                    scale(m.msg)
            if detections_yaw_deg and m.topic == "/landmark_detections":
                c, s = math.cos(math.radians(detections_yaw_deg)), math.sin(
                    math.radians(detections_yaw_deg)
                )
                for pose in m.msg.poses:
                    x, y = pose.position.x, pose.position.y
                    pose.position.x, pose.position.y = c * x - s * y, s * x + c * y
            if sonar_dt and m.topic in order:
                shift = order[m.topic] * sonar_dt
                m.msg.header.stamp = M.stamp(M.stamp_to_sec(m.msg.header.stamp) + shift)
                t += shift
            w.write(m.topic, m.typename, m.msg, t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("src", type=Path, help="directory with log.mcap (and truth.tum)")
    ap.add_argument("dst", type=Path, help="directory to create")
    ap.add_argument("--sonar-sequential", type=float, default=0.0, metavar="DT")
    ap.add_argument("--odometry-every", type=int, default=1, metavar="N")
    ap.add_argument("--odometry-scale", default="1,1", metavar="D,T")
    ap.add_argument("--detections-yaw", type=float, default=0.0, metavar="DEG")
    a = ap.parse_args()
    d, t = (float(v) for v in a.odometry_scale.split(","))
    a.dst.mkdir(parents=True, exist_ok=False)
    write_variant(
        a.src / "log.mcap", a.dst / "log.mcap", a.sonar_sequential, a.odometry_every, (d, t),
        a.detections_yaw,
    )  # fmt: skip
    for name in ("truth.tum", "landmarks_truth.yaml"):
        if (a.src / name).is_file():
            (a.dst / name).symlink_to((a.src / name).resolve())


if __name__ == "__main__":
    main()
