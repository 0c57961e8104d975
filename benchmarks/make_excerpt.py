"""Cut a short excerpt of a landmark log (odometry, detections, ground truth) for the tests.

    python benchmarks/make_excerpt.py LOG.mcap TRUTH.tum LANDMARKS.yaml OUTDIR \
        --start 60 --duration 120 --odom-every 5 [--tum-every 10]

Writes OUTDIR/log.mcap (the same messages, byte for byte, of the topics kept, between
start and start + duration seconds of the log; every n-th odometry message: poses are
cumulative, so thinning the odometry loses no motion), OUTDIR/truth.tum (the truth rows of
the same span) and a copy of the landmark truth. The committed excerpt in data/real/ was
made this way (see its README).
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.typestore import serialize
from fuzzyslam.streams.writer import LogWriter


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log")
    ap.add_argument("truth")
    ap.add_argument("landmarks")
    ap.add_argument("outdir")
    ap.add_argument("--start", type=float, default=60.0, help="seconds after the log's start")
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--odom-every", type=int, default=5)
    ap.add_argument("--truth-every", type=int, default=2)
    ap.add_argument("--tum-every", type=int, default=1, help="keep every n-th row of truth.tum")
    ap.add_argument("--topics", default="/odom,/landmark_detections,/ground_truth/odom")
    a = ap.parse_args()
    out = Path(a.outdir)
    out.mkdir(parents=True, exist_ok=True)
    reader = LogReader(a.log)
    t0 = reader.start + a.start
    t1 = t0 + a.duration
    topics = a.topics.split(",")
    seen = dict.fromkeys(topics, 0)
    with LogWriter(out / "log.mcap") as w:
        for m in reader.messages(topics):
            if not t0 <= m.t <= t1:
                continue
            seen[m.topic] += 1
            every = {topics[0]: a.odom_every, topics[2]: a.truth_every}.get(m.topic, 1)
            if (seen[m.topic] - 1) % every:
                continue
            w.write_cdr(m.topic, m.typename, serialize(m.msg, m.typename), m.t)
    lines = Path(a.truth).read_text(encoding="utf-8").splitlines()
    rows = [ln for ln in lines if not ln.startswith("#")]
    rows = [ln for ln in rows if t0 - 1 <= float(ln.split()[0]) <= t1 + 1]
    keep = [ln for ln in lines if ln.startswith("#")] + rows[:: a.tum_every]
    (out / "truth.tum").write_text("\n".join(keep) + "\n", encoding="utf-8")
    shutil.copyfile(a.landmarks, out / "landmarks_truth.yaml")


if __name__ == "__main__":
    main()
