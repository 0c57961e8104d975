"""Cut the committed excerpt from the CARMEN Freiburg 079 log (see README.md beside it).

Run: python data/carmen_fr079_excerpt/cut.py SRC_DIR [--start S] [--length L]

SRC_DIR holds ``log.mcap`` and ``truth.tum`` (the conversion described in README.md).
Writes ``log.mcap`` (the /scan, /sonar/sNN, /odom, /ground_truth/odom and /tf_static
messages logged in [t0 + S, t0 + S + L], /tf_static kept whole) and ``truth.tum`` (the
truth's lines in the same window) next to this script.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.writer import LogWriter

HERE = Path(__file__).resolve().parent


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("src", type=Path)
    ap.add_argument("--start", type=float, default=150.0)
    ap.add_argument("--length", type=float, default=60.0)
    a = ap.parse_args()
    reader = LogReader(a.src / "log.mcap")
    t0 = reader.start + a.start
    t1 = t0 + a.length
    with LogWriter(HERE / "log.mcap") as w:
        for m in reader.messages():
            keep = m.topic == "/tf_static" or t0 <= m.t <= t1
            if keep and not m.topic.startswith("/sim"):
                w.write(m.topic, m.typename, m.msg, max(m.t, t0))
    lines = (a.src / "truth.tum").read_text(encoding="utf-8").splitlines()
    out = [ln for ln in lines if ln.startswith("#") or t0 <= float(ln.split()[0]) <= t1]
    (HERE / "truth.tum").write_text("\n".join(out) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
