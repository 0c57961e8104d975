"""Benchmark `fuzzyslam simulate` on the full paper scenario (run on demand, not a test).

Prints wall time, real-time factor, file size and peak memory (resource.getrusage),
plus the simulation's own summary figures. With ``--baseline REV`` (e.g. main) it also
runs ``fuzzyslam simulate`` of the old code (git revision REV) and of this code side by
side, alternating, ``--repeat`` times each, and prints their CPU and wall times, the
speed-up and whether the two logs are byte-identical. Usage:

    python benchmarks/bench_simulate.py [CONFIG] [--seed N] [--out FILE]
    python benchmarks/bench_simulate.py paper --baseline main --repeat 3
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("config", nargs="?", default="paper")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None)
    ap.add_argument("--baseline", metavar="REV", default=None,
                    help="git revision of the old code to time side by side")  # fmt: skip
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    if args.baseline:
        side_by_side_simulate(args)
        return
    os.environ.setdefault("FUZZYSLAM_NO_PROGRESS", "1")
    from fuzzyslam.config import load_config
    from fuzzyslam.sim.record import simulate_to_mcap

    cfg = load_config(args.config, args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(args.out) if args.out else Path(tmp) / "bench.mcap"
        t0 = time.perf_counter()
        summary, _plan = simulate_to_mcap(cfg, out)
        wall = time.perf_counter() - t0
        size = out.stat().st_size
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    figures = {
        "config": args.config,
        "seed": args.seed,
        "wall_time_s": round(wall, 2),
        "simulated_s": summary["duration_s"],
        "real_time_factor": round(summary["duration_s"] / wall, 1),
        "file_size_mb": round(size / 1e6, 2),
        "peak_rss_mb": round(peak_kb / 1024, 1),
        "messages_total": summary["messages_total"],
        "dead_reckoning_end_error_m": summary["dead_reckoning_end_error_m"],
        "dead_reckoning_max_error_m": summary["dead_reckoning_max_error_m"],
        "frames_two_lamps_fraction": summary["frames_two_lamps_fraction"],
        "frames_two_lamps_fraction_all_lamps_on": summary["frames_two_lamps_fraction_all_lamps_on"],
        "sonar_no_echo_fraction": summary["sonar_no_echo_fraction"],
        "targets": {"wall_time_s": 30, "file_size_mb": 100, "peak_rss_mb": 1024},
    }
    json.dump(figures, sys.stdout, indent=2)
    print()


def side_by_side_simulate(args) -> None:
    """Old (``--baseline``) and new ``fuzzyslam simulate`` alternately; identical bytes?"""
    import filecmp

    sys.path.insert(0, str(Path(__file__).parent))
    from sidebyside import export_revision, load, side_by_side

    src = export_revision(args.baseline)
    with tempfile.TemporaryDirectory() as tmp:
        logs = {v: Path(tmp) / f"{v}.mcap" for v in ("old", "new")}
        before = load()
        res = side_by_side(lambda v: ["simulate", args.config, "-o", str(logs[v]), "--seed",
                                      str(args.seed)], src, args.repeat)  # fmt: skip
        same = filecmp.cmp(logs["old"], logs["new"], shallow=False)
        size = logs["new"].stat().st_size
    json.dump({"command": f"fuzzyslam simulate {args.config} --seed {args.seed}",
               "baseline": args.baseline, "repeat": args.repeat, **res,
               "logs_byte_identical": same, "file_size_mb": round(size / 1e6, 2),
               "load_before": before, "load_after": load()}, sys.stdout, indent=2)  # fmt: skip
    print()


if __name__ == "__main__":
    main()
