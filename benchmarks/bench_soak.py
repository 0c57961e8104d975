"""Soak benchmark (issue 7): a recording N times the paper's length through run and map.

    python benchmarks/bench_soak.py [--factor 10] [--workdir DIR] [--keep] [--reuse] [--steady]

Simulates the paper log (6 runs) and a log ``factor`` times longer (6 x factor runs,
the same world and lamp failures), then runs ``fuzzyslam run`` and ``fuzzyslam map
--until-run LAST`` (the map over the whole log, not only the paper's first four runs)
on both, each stage in its own child process. For each stage it prints the wall and
CPU time, the cost per second of log (CPU s / log s), the ratio of that cost long /
short (1.0 = linear in the log length) and the peak RSS (``ru_maxrss`` of the child,
read with ``resource.getrusage(RUSAGE_CHILDREN)`` in a wrapper process that runs only
that stage). Flat memory means the long log's peak RSS stays close to the short one's
rather than growing ``factor`` times.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

# Runs one command as a child and prints its resource use as JSON (one wrapper per
# stage, so RUSAGE_CHILDREN is that stage's alone).
WRAPPER = r"""
import json, resource, subprocess, sys, time
w0 = time.perf_counter()
p = subprocess.run(sys.argv[1:], stdout=subprocess.PIPE)
wall = time.perf_counter() - w0
ru = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"rc": p.returncode, "wall": wall, "cpu": ru.ru_utime + ru.ru_stime,
                  "maxrss_mb": ru.ru_maxrss / 1024, "stdout": p.stdout.decode()}))
"""

PAPER_RUNS = 6


def measured(cmd: list[str]) -> dict:
    env = dict(os.environ, FUZZYSLAM_NO_PROGRESS="1")
    out = subprocess.run(
        [sys.executable, "-c", WRAPPER, *cmd], env=env, check=True, stdout=subprocess.PIPE
    ).stdout.decode()
    res = json.loads(out)
    if res["rc"] != 0:
        raise SystemExit(f"failed ({res['rc']}): {' '.join(cmd)}")
    res["summary"] = json.loads(res.pop("stdout"))
    return res


def fuzzyslam(*args: str | Path) -> list[str]:
    return [sys.executable, "-m", "fuzzyslam", *(str(a) for a in args)]


def soak(workdir: Path, factor: int, reuse: bool = False, steady: bool = False) -> None:
    # --steady: no lamp failures. With the paper's failures (7 of 15 lamps dark from run
    # 5 on) and no heading fixes, every dark stretch lets the pose drift and lamps seen
    # again become duplicates: the state grows with the log, and so does the update
    # cost (O(n^2) in the lamps): the paper's failure mode, not the code's cost.
    extra = "  lamp_failures: []\n" if steady else ""
    tag = "_steady" if steady else ""
    short_cfg = workdir / f"paper{tag}.yaml"
    if steady:
        short_cfg.write_text(
            f"extends: paper.yaml\nname: paper{tag}\nscenario:\n{extra}", encoding="utf-8"
        )
    long_cfg = workdir / f"soak{tag}.yaml"
    long_cfg.write_text(
        f"extends: paper.yaml\nname: soak_x{factor}{tag}\nscenario:\n"
        f"  runs: {PAPER_RUNS * factor}\n{extra}",
        encoding="utf-8",
    )
    rows = []
    for name, cfg, runs in (
        (f"paper{tag}", str(short_cfg) if steady else "paper", PAPER_RUNS),
        (f"x{factor}{tag}", str(long_cfg), PAPER_RUNS * factor),
    ):
        log = workdir / f"{name}.mcap"
        stages = {}
        if not (reuse and log.exists()):
            stages["simulate"] = measured(fuzzyslam("simulate", cfg, "-o", log))
        size = log.stat().st_size / 1e6
        est = workdir / f"{name}_est"
        run = measured(fuzzyslam("run", log, "-o", est, "--config", cfg))
        dur = run["summary"]["log_duration_s"]
        fgm = workdir / f"{name}_fgm"
        map_args = ["--config", cfg, "--until-run", runs, "--no-figures"]
        mp = measured(
            fuzzyslam("map", log, "--trajectory", est / "trajectory.tum", "-o", fgm, *map_args)
        )
        stages.update({"run": run, "map": mp})
        rows.append((name, dur, size, stages))
        print(
            f"{name}: {runs} runs, {dur:.0f} s of log, {size:.0f} MB; "
            f"run: {run['summary']['lamps']} lamps, "
            f"{run['summary']['trajectory_rows']} rows, "
            f"final sigma {run['summary']['final_pose_sigma']}; "
            f"diverged: {run['summary'].get('filter_health', {}).get('diverged')}; "
            f"map: {mp['summary']['rings_used']} rings",
            flush=True,
        )
    print()
    print(f"{'stage':<9} {'log':<12} {'log s':>7} {'wall s':>7} {'CPU s':>7} "
          f"{'CPU ms/log s':>12} {'ratio':>6} {'peak RSS MB':>11}")  # fmt: skip
    base = {}
    for name, dur, _size, stages in rows:
        for stage, r in stages.items():
            per = 1000 * r["cpu"] / dur
            ratio = per / base[stage] if stage in base else 1.0
            base.setdefault(stage, per)
            print(
                f"{stage:<9} {name:<12} {dur:>7.0f} {r['wall']:>7.1f} {r['cpu']:>7.1f} "
                f"{per:>12.2f} {ratio:>6.2f} {r['maxrss_mb']:>11.0f}"
            )
    print(
        f"\nratio = CPU per second of log, long / paper (1.00: linear cost); "
        f"peak RSS: the stage's own child process. {os.cpu_count()} cores, "
        f"load average {os.getloadavg()[0]:.2f}."
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factor", type=int, default=10, help="long log = factor x paper runs")
    ap.add_argument("--workdir", type=Path, default=None, help="where to write (default: tmp)")
    ap.add_argument("--keep", action="store_true", help="keep the logs and outputs")
    ap.add_argument("--reuse", action="store_true", help="reuse logs already in --workdir")
    ap.add_argument(
        "--steady",
        action="store_true",
        help="no lamp failures (a map of constant size: the cost of the code alone)",
    )
    a = ap.parse_args()
    work = a.workdir or Path(tempfile.mkdtemp(prefix="fuzzyslam_soak_"))
    work.mkdir(parents=True, exist_ok=True)
    try:
        soak(work, a.factor, a.reuse, a.steady)
    finally:
        if not a.keep and a.workdir is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
