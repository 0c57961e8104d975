"""Benchmark of ``fuzzyslam reproduce``: the whole experiment for one seed, wall time.

    python benchmarks/bench_reproduce.py [--seeds 1] [--jobs N] [--workdir DIR]

Runs ``reproduce --paper-only`` (the paper's phases A-D: two simulations, three runs, a
map, three evaluations; target: under 60 s on 2 cores) and the full ``reproduce`` (plus
the all-lamps-off and people scenarios, pose fixes), each in a fresh directory and its own
process, and prints one JSON object per variant: wall time, the sum of the steps' times
(the work), the work of each kind of step, and two lower bounds of the wall time: the
longest chain of dependent steps (measured times) and the work divided by the jobs.

With ``--baseline REV`` (e.g. main) each variant also runs with the old code (git revision
REV), alternating old and new ``--repeat`` times: wall and CPU time (user + sys of every
process of the run) of both, the speed-up, whether the two reports' tables are the same,
and the target (one seed: <= 30 s wall on 2 cores).

    python benchmarks/bench_reproduce.py --seeds 1 --baseline main --only full

``--quick``: the two-run scenarios (``reproduce --quick``), e.g. the test suite's plans.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path


def chain_bound(steps: list[dict], deps: dict[str, tuple[str, ...]]) -> float:
    """Longest path through the step graph with the measured step times."""
    t = {s["key"]: s["seconds"] for s in steps}
    memo: dict[str, float] = {}

    def finish(k: str) -> float:
        if k not in memo:
            memo[k] = t[k] + max((finish(d) for d in deps[k]), default=0.0)
        return memo[k]

    return max(finish(k) for k in t)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--only", choices=["paper", "full"], default=None)
    ap.add_argument("--baseline", metavar="REV", default=None,
                    help="git revision of the old code to time side by side")  # fmt: skip
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--quick", action="store_true", help="reproduce --quick")
    args = ap.parse_args()
    if args.baseline:
        side_by_side_reproduce(args)
        return

    from fuzzyslam.reproduce.plan import FULL, QUICK, build_plan

    work = args.workdir or Path(tempfile.mkdtemp(prefix="bench_reproduce."))
    env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "MPLBACKEND": "Agg"}
    quick = ["--quick"] if args.quick else []
    variants = [("paper", ["--paper-only", *quick]), ("full", quick)]
    for name, extra in variants:
        if args.only and name != args.only:
            continue
        out = work / f"reproduce_{name}"
        cmd = [sys.executable, "-m", "fuzzyslam", "reproduce", "-o", str(out),
               "--seeds", str(args.seeds), "--jobs", str(args.jobs), *extra]  # fmt: skip
        t0 = time.perf_counter()
        p = subprocess.run(cmd, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        if p.returncode != 0:
            print(json.dumps({"variant": name, "error": p.stderr.strip()}))
            continue
        res = json.loads((out / "results.json").read_text())
        steps = res["steps"]
        suite = QUICK if args.quick else FULL
        plan = build_plan(list(range(args.seeds)), suite, beyond=(name == "full"))
        deps = {s.key: s.deps for s in plan}
        by_kind: dict[str, float] = defaultdict(float)
        for s in steps:
            by_kind[s["command"].split()[1]] += s["seconds"]
        work_s = sum(s["seconds"] for s in steps)
        print(json.dumps({
            "variant": name,
            "seeds": args.seeds,
            "jobs": args.jobs,
            "wall_s": round(wall, 1),
            "quick": args.quick,
            "target_wall_s": 60.0 if name == "paper" and args.seeds == 1 and not quick else None,
            "work_s": round(work_s, 1),
            "work_by_command_s": {k: round(v, 1) for k, v in sorted(by_kind.items())},
            "bound_longest_chain_s": round(chain_bound(steps, deps), 1),
            "bound_work_over_jobs_s": round(work_s / args.jobs, 1),
            "steps": len(steps),
        }))  # fmt: skip


def side_by_side_reproduce(args) -> None:
    """Old (``--baseline``) and new ``reproduce`` alternately, per variant."""
    sys.path.insert(0, str(Path(__file__).parent))
    from sidebyside import export_revision, load, same_outputs, side_by_side

    src = export_revision(args.baseline)
    work = args.workdir or Path(tempfile.mkdtemp(prefix="bench_reproduce."))
    work.mkdir(parents=True, exist_ok=True)
    quick = ["--quick"] if args.quick else []
    for name, extra in (("paper", ["--paper-only", *quick]), ("full", quick)):
        if args.only and name != args.only:
            continue
        outs = {v: work / f"{name}_{v}" for v in ("old", "new")}
        before = load()
        res = side_by_side(lambda v, outs=outs, extra=extra: [
            "reproduce", "-o", str(outs[v]), "--seeds", str(args.seeds), "--jobs",
            str(args.jobs), *extra], src, args.repeat)  # fmt: skip
        tables = [[ln for ln in (outs[v] / "report.md").read_text().splitlines()
                   if ln.startswith("| ") and "Cost" not in ln and "time" not in ln]
                  for v in ("old", "new")]  # fmt: skip
        print(json.dumps({"variant": name, "quick": args.quick, "seeds": args.seeds,
                          "same_files": same_outputs(outs["old"], outs["new"]),
                          "jobs": args.jobs,
                          "baseline": args.baseline, **res,
                          "target_wall_s": 30.0 if args.seeds == 1 and name == "full"
                          and not args.quick else None,
                          "same_table": tables[0] == tables[1],
                          "load_before": before, "load_after": load()}, indent=2))  # fmt: skip


if __name__ == "__main__":
    main()
