"""Benchmark `fuzzyslam simulate` on the full paper scenario (run on demand, not a test).

Prints wall time, real-time factor, file size and peak memory (resource.getrusage),
plus the simulation's own summary figures. Usage:

    python benchmarks/bench_simulate.py [CONFIG] [--seed N] [--out FILE]
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
    args = ap.parse_args()
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


if __name__ == "__main__":
    main()
