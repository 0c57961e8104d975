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

SRC and DST are directories holding ``log.mcap`` (and ``truth.tum``, linked into DST), so
that ``bench_buildings.py --data`` reads DST's parent as it reads the real logs. The
README's figures for restamped sonars and slow odometry come from these variants of
the CARMEN logs, e.g.::

    python benchmarks/log_variants.py ../shared/data/real/carmen-aces /tmp/v/carmen-aces \\
        --odometry-every 5
    python benchmarks/bench_buildings.py --data /tmp/v
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.writer import LogWriter


def write_variant(src: Path, dst: Path, sonar_dt: float = 0.0, odometry_every: int = 1) -> None:
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
    """
    reader = LogReader(src)
    order = {
        tp: k for k, tp in enumerate(sorted(t for t in reader.topics if t.startswith("/sonar/s")))
    }
    seen = 0
    with LogWriter(dst) as w:
        for name in sorted(reader.metadata):
            w.metadata(name, reader.metadata[name])
        for m in reader.messages():
            t = m.t
            if m.topic == "/odom":
                seen += 1
                if (seen - 1) % odometry_every:
                    continue
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
    a = ap.parse_args()
    a.dst.mkdir(parents=True, exist_ok=False)
    write_variant(a.src / "log.mcap", a.dst / "log.mcap", a.sonar_sequential, a.odometry_every)
    if (a.src / "truth.tum").is_file():
        (a.dst / "truth.tum").symlink_to((a.src / "truth.tum").resolve())


if __name__ == "__main__":
    main()
