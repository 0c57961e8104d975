"""Benchmark of the CLI's BLAS pinning: `fuzzyslam run` on a 75-lamp world, with the
CLI's one BLAS thread per process and with the BLAS library's default thread count.

    python benchmarks/bench_blas.py [--lamps 75] [--config paper.yaml] [--repeat 3]

Simulates the config's world with ``world.lamp_count`` lamps once, then times the same
``fuzzyslam run`` command (a fresh process each time, so the library reads its thread
count at load) alternately in the two environments: ``pinned`` (the CLI's default,
FUZZYSLAM_BLAS_THREADS unset) and ``default`` (FUZZYSLAM_BLAS_THREADS=default: OpenBLAS
starts one thread per core). Prints the best and median wall time of each, their ratio,
the machine's load average and its core count.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fuzzyslam.cli import BLAS_VARIABLES


def fuzzyslam(args: list[str], blas: str) -> float:
    """Wall seconds of ``fuzzyslam ARGS`` in a fresh process with ``blas`` threading."""
    env = {k: v for k, v in os.environ.items() if k not in BLAS_VARIABLES}
    env["FUZZYSLAM_NO_PROGRESS"] = "1"
    env.pop("FUZZYSLAM_BLAS_THREADS", None)
    if blas == "default":
        env["FUZZYSLAM_BLAS_THREADS"] = "default"
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "fuzzyslam", *args], env=env, check=True,
                   stdout=subprocess.DEVNULL)  # fmt: skip
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lamps", type=int, default=75)
    ap.add_argument("--config", default="paper.yaml")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        cfg = Path(d) / "lamps.yaml"
        cfg.write_text(f"extends: {a.config}\nworld:\n  lamp_count: {a.lamps}\n  lamps: []\n")
        log = Path(d) / "lamps.mcap"
        sim = fuzzyslam(["simulate", str(cfg), "-o", str(log), "--seed", "0"], "pinned")
        print(f"simulated {a.config} with {a.lamps} lamps in {sim:.1f} s")
        times: dict[str, list[float]] = {"pinned": [], "default": []}
        load0 = os.getloadavg()[0]
        for _ in range(a.repeat):
            for blas in times:
                args = ["run", str(log), "-o", str(Path(d) / f"est_{blas}"), "--config", str(cfg)]
                times[blas].append(fuzzyslam(args, blas))
        load1 = os.getloadavg()[0]
    for blas, t in times.items():
        print(f"run, {a.lamps} lamps, BLAS {blas:7s}: best {min(t):.2f} s, "
              f"median {statistics.median(t):.2f} s over {len(t)} ({', '.join(f'{x:.2f}' for x in t)})")  # noqa: E501
    ratio = min(times["default"]) / min(times["pinned"])
    print(f"default / pinned (best): {ratio:.2f}x; load average {load0:.2f} -> {load1:.2f} "
          f"on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
