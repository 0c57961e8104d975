"""Benchmark of `fuzzyslam run`: real-time factor on the paper log, update cost vs lamps.

    python benchmarks/bench_run.py [LOG.mcap]    # default: simulates the paper log in /tmp

Prints (1) wall and CPU time of the whole run stage (read, detect, filter, write) and the
real-time factor (log duration / wall time), (2) the cost of one EKF step against the
number of lamps in the state n = 15, 100, 1000: prediction (O(n)), a joint update with
two lamps (O(n^2)), the individual compatibility of 3 detections against all lamps (O(n)),
and the growth exponent log(cost ratio) / log(n ratio), which must stay <= 2. Below ~100
lamps a step costs mostly Python/numpy call overhead; from 1000 lamps P (16 MB+) leaves
the caches, so 1000 -> 2000 shows the asymptotic exponent.

With ``--baseline REV`` (e.g. main) it instead times ``fuzzyslam run`` of the old code
(git revision REV) and of this code side by side, alternating, ``--repeat`` times each, on
the paper log: lamps only, heading fixes and pose fixes (from the FGM of the lamps-only
run), with the real-time factors (log duration / CPU and / wall time) against the targets
(>= 500x lamps only, >= 300x with fixes) and whether the outputs are byte-identical
(summary.json without its timing fields).

    python benchmarks/bench_run.py [LOG.mcap] --baseline main --repeat 3

``--calibration`` (with ``--baseline``) times the lamps-only run with the odometry
self-calibration off and on (``slam.calibrate``, a config that extends paper.yaml), old
and new code alternating, and prints each code's on/off CPU ratio (the calibration's
cost) and whether the outputs of both settings are byte-identical to the old code's.

    python benchmarks/bench_run.py LOG.mcap --baseline main --calibration --repeat 5

``--prefetch`` times this code's ``fuzzyslam run`` with its events made in a child
process (``--prefetch``, the default where there are two CPUs) and in one process
(``--no-prefetch``) alternately (the order swapped every round), fresh processes, on the
paper log: lamps only, heading and pose fixes; wall and CPU (the child's included: it is
waited for) medians, and whether the outputs are byte-identical.

    python benchmarks/bench_run.py [LOG.mcap] --prefetch --repeat 5

``--sample`` (with ``--baseline``) times ``fuzzyslam run data/sample.mcap`` (121 s of log)
instead, old and new alternately: the command's start-up weighs most there.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("FUZZYSLAM_NO_PROGRESS", "1")
# one BLAS thread: on a shared 2-core machine OpenBLAS's threads wait for a busy core and
# make the large-n update times bimodal (7 vs 110 ms at n = 1000); set before numpy loads
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

from fuzzyslam.config import load_config
from fuzzyslam.slam.association import block_diag_cov
from fuzzyslam.slam.ekf import EkfSlam
from fuzzyslam.slam.stage import run_stage


def bench_log(log: Path) -> None:
    cfg = load_config("paper")
    with tempfile.TemporaryDirectory() as d:
        best = None
        for _ in range(3):
            c0, w0 = time.process_time(), time.perf_counter()
            s = run_stage(log, Path(d) / "out", cfg)
            wall, cpu = time.perf_counter() - w0, time.process_time() - c0
            best = (wall, cpu) if best is None or wall < best[0] else best
    dur = s["log_duration_s"]
    print(
        f"log {log}: {dur:.1f} s, {s['counts']['frames']} frames, "
        f"{s['counts']['odometry']} odometry steps, {s['lamps']} lamps"
    )
    print(
        f"run stage (best of 3): wall {best[0]:.2f} s, CPU {best[1]:.2f} s, "
        f"real-time factor {dur / best[0]:.0f}x (wall), {dur / best[1]:.0f}x (CPU); "
        f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores; "
        f"peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB"
    )


def filled_filter(n: int, rng: np.random.Generator) -> EkfSlam:
    ekf = EkfSlam([0.0, 0.0, 0.0], np.eye(3) * 1e-4, load_config("paper").slam.odometry_noise, n)
    for _ in range(n):
        ekf.add_lamp(rng.uniform(-3, 3, 2), np.eye(2) * 1e-4)
        ekf.predict(0.01, 0.001)
    return ekf


def per_call(f, reps: int, rounds: int = 5) -> float:
    """Best (minimum) over ``rounds`` of the mean time of ``reps`` calls: robust to the
    other processes of a shared machine."""
    f()
    best = np.inf
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(reps):
            f()
        best = min(best, (time.perf_counter() - t0) / reps)
    return best


def bench_scaling() -> None:
    rng = np.random.default_rng(0)
    sizes = (15, 100, 1000, 2000)
    rows = {}
    for n in sizes:
        ekf = filled_filter(n, rng)
        r = block_diag_cov(np.repeat((np.eye(2) * 1e-4)[None], 2, axis=0))
        z = ekf.predict_lamps([0, 1])[0].reshape(2, 2)
        dets = rng.uniform(-2, 2, (3, 2))
        reps = 500 if n < 500 else 4
        rows[n] = (
            per_call(lambda ekf=ekf: ekf.predict(0.01, 0.001), reps),
            per_call(lambda ekf=ekf, z=z, r=r: ekf.update_lamps([0, 1], z, r), reps),
            per_call(
                lambda ekf=ekf, d=dets: ekf.individual_compatibility(d, np.eye(2) * 1e-4), reps
            ),
        )
    print("lamps   predict(us)  update 2 lamps(us)  compat 3 dets(us)")
    for n in sizes:
        p, u, c = rows[n]
        print(f"{n:5d}   {p * 1e6:10.1f}  {u * 1e6:18.1f}  {c * 1e6:17.1f}")
    for a, b in ((15, 100), (100, 1000), (1000, 2000)):
        ex = [np.log(rows[b][k] / rows[a][k]) / np.log(b / a) for k in range(3)]
        print(
            f"growth exponent {a}->{b}: predict {ex[0]:.2f}, update {ex[1]:.2f}, "
            f"compat {ex[2]:.2f} (must be <= 2)"
        )


def side_by_side_run(log: Path, rev: str, repeat: int, candidate: str | None = None) -> None:
    """Old (``rev``) and new ``fuzzyslam run`` alternately: lamps only, heading, pose (new:
    the installed code, or git revision ``candidate``)."""
    import json

    sys.path.insert(0, str(Path(__file__).parent))
    from sidebyside import export_revision, load, run_cli, same_outputs, side_by_side

    from fuzzyslam.streams.reader import LogReader

    reader = LogReader(log)
    duration = reader.end - reader.start
    src = export_revision(rev)
    new = export_revision(candidate) if candidate else None
    work = Path(tempfile.mkdtemp(prefix="bench_run."))
    run_cli(["run", str(log), "-o", str(work / "AB"), "--config", "paper"], new)
    run_cli(["map", str(log), "--trajectory", str(work / "AB" / "trajectory.tum"),
             "--landmarks", str(work / "AB" / "landmarks.yaml"), "-o", str(work / "fgm"),
             "--config", "paper"], new)  # fmt: skip
    for name, extra, target in (("lamps only", [], 500), ("heading fixes", ["heading"], 300),
                                ("pose fixes", ["pose"], 300)):  # fmt: skip
        fix = ["--map", str(work / "fgm"), "--fix", extra[0]] if extra else []
        outs = {v: work / f"{name.split()[0]}_{v}" for v in ("old", "new")}
        before = load()
        res = side_by_side(lambda v, outs=outs, fix=fix: [
            "run", str(log), "-o", str(outs[v]), "--config", "paper", *fix],
            src, repeat, new)  # fmt: skip
        for v in ("old", "new"):
            res[v]["real_time_factor_cpu"] = round(duration / res[v]["cpu_median_s"])
            res[v]["real_time_factor_wall"] = round(duration / res[v]["wall_median_s"])
        same = same_outputs(outs["old"], outs["new"])["identical"]
        print(json.dumps({"run": name, "log_s": round(duration, 1), "baseline": rev,
                          "candidate": candidate or "installed",
                          "repeat": repeat, **res, "target_real_time_factor": target,
                          "outputs_byte_identical": same,
                          "load_before": before, "load_after": load()}, indent=2))  # fmt: skip


def side_by_side_prefetch(log: Path, repeat: int) -> None:
    """``fuzzyslam run --no-prefetch`` and ``--prefetch`` (this code) alternately, the
    order swapped every round: lamps only, heading, pose (module docstring)."""
    import json
    import statistics

    sys.path.insert(0, str(Path(__file__).parent))
    from sidebyside import ROOT, compiled, load, run_cli, same_outputs

    from fuzzyslam.streams.reader import LogReader

    reader = LogReader(log)
    duration = reader.end - reader.start
    compiled(ROOT / "fuzzyslam")
    work = Path(tempfile.mkdtemp(prefix="bench_prefetch."))
    run_cli(["run", str(log), "-o", str(work / "AB"), "--config", "paper"], None)
    run_cli(["map", str(log), "--trajectory", str(work / "AB" / "trajectory.tum"),
             "--landmarks", str(work / "AB" / "landmarks.yaml"), "-o", str(work / "fgm"),
             "--config", "paper"], None)  # fmt: skip
    fgm = ["--map", str(work / "fgm"), "--fix"]
    for name, fix, target in (("lamps only", [], 500), ("heading fixes", [*fgm, "heading"], 300),
                              ("pose fixes", [*fgm, "pose"], 300)):  # fmt: skip
        before = load()
        times: dict[str, list[tuple[float, float]]] = {"one process": [], "child": []}
        outs = {v: work / f"{name.split()[0]}_{v.replace(' ', '_')}" for v in times}
        flag = {"one process": "--no-prefetch", "child": "--prefetch"}
        for i in range(repeat):
            for v in ("one process", "child") if i % 2 == 0 else ("child", "one process"):
                args = ["run", str(log), "-o", str(outs[v]), "--config", "paper", *fix, flag[v]]
                times[v].append(run_cli(args, None))
        res = {}
        for v, rows in times.items():
            walls, cpus = [w for w, _ in rows], [c for _, c in rows]
            wall, cpu = statistics.median(walls), statistics.median(cpus)
            res[v] = {"wall_median_s": round(wall, 2), "wall_best_s": round(min(walls), 2),
                      "cpu_median_s": round(cpu, 2), "cpu_best_s": round(min(cpus), 2),
                      "real_time_factor_wall": round(duration / wall),
                      "real_time_factor_cpu": round(duration / cpu)}  # fmt: skip
        same = same_outputs(outs["one process"], outs["child"])["identical"]
        print(json.dumps({"run": name, "log_s": round(duration, 1), "repeat": repeat, **res,
                          "wall_ratio": round(res["one process"]["wall_median_s"]
                                              / res["child"]["wall_median_s"], 2),
                          "target_real_time_factor": target,
                          "outputs_byte_identical": same,
                          "load_before": before, "load_after": load()}, indent=2))  # fmt: skip


def side_by_side_calibration(log: Path, rev: str, repeat: int,
                              candidate: str | None = None) -> None:  # fmt: skip
    """Old (``rev``) and new ``fuzzyslam run`` lamps only, calibration off and on, the four
    alternating: each code's CPU medians and its on/off ratio, outputs compared."""
    import json
    import statistics

    sys.path.insert(0, str(Path(__file__).parent))
    from sidebyside import compiled, export_revision, load, run_cli, same_outputs

    from fuzzyslam.reproduce.overrides import override_text
    from fuzzyslam.streams.reader import LogReader

    reader = LogReader(log)
    duration = reader.end - reader.start
    codes = {"old": export_revision(rev), "new": export_revision(candidate) if candidate else None}
    for code in codes.values():
        compiled(code or Path(__file__).resolve().parents[1] / "fuzzyslam")
    work = Path(tempfile.mkdtemp(prefix="bench_run_calibration."))
    on = work / "calibrated.yaml"
    on.write_text(override_text("paper.yaml", {"slam.calibrate": True}, "bench_run.py"))
    configs = {"off": "paper", "on": str(on)}
    cpu: dict[str, list[float]] = {}
    before = load()
    for _ in range(repeat):
        for v, code in codes.items():
            for c, cfg in configs.items():
                out = work / f"{v}_{c}"
                cpu.setdefault(f"{v}_{c}", []).append(
                    run_cli(["run", str(log), "-o", str(out), "--config", cfg], code)[1]
                )
    med = {k: round(statistics.median(t), 3) for k, t in cpu.items()}
    print(json.dumps({"run": "lamps only, calibration off and on", "log_s": round(duration, 1),
                      "baseline": rev, "candidate": candidate or "installed",
                      "repeat": repeat, "cpu_median_s": med,
                      "on_off_ratio": {v: round(med[f"{v}_on"] / med[f"{v}_off"], 3)
                                       for v in codes},
                      "speedup_on_cpu_median": round(med["old_on"] / med["new_on"], 3),
                      "outputs_byte_identical": {
                          c: same_outputs(work / f"old_{c}", work / f"new_{c}")["identical"]
                          for c in configs},
                      "load_before": before, "load_after": load()}, indent=2))  # fmt: skip


def side_by_side_sample(rev: str, repeat: int, candidate: str | None = None) -> None:
    """Old (``rev``) and new ``fuzzyslam run`` of the committed sample log (121 s, lamps
    only) alternately: a short run, where the command's start-up (imports, typestores)
    weighs most."""
    import json

    sys.path.insert(0, str(Path(__file__).parent))
    from sidebyside import export_revision, load, same_outputs, side_by_side

    log = Path(__file__).resolve().parents[1] / "data" / "sample.mcap"
    src = export_revision(rev)
    new = export_revision(candidate) if candidate else None
    work = Path(tempfile.mkdtemp(prefix="bench_run_sample."))
    before = load()
    res = side_by_side(lambda v: ["run", str(log), "-o", str(work / v)], src, repeat, new)
    same = same_outputs(work / "old", work / "new")["identical"]
    print(json.dumps({"run": "sample log, lamps only", "baseline": rev,
                      "candidate": candidate or "installed", "repeat": repeat, **res,
                      "outputs_byte_identical": same,
                      "load_before": before, "load_after": load()}, indent=2))  # fmt: skip


def main() -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", nargs="?", default=None)
    ap.add_argument("--baseline", metavar="REV", default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--sample", action="store_true",
                    help="with --baseline: run the sample log instead (start-up)")  # fmt: skip
    ap.add_argument("--calibration", action="store_true",
                    help="with --baseline: lamps only, calibration off and on")  # fmt: skip
    ap.add_argument("--prefetch", action="store_true",
                    help="this code with and without its input process, alternately")  # fmt: skip
    ap.add_argument("--candidate", metavar="REV", default=None,
                    help="the new code: a git revision (default: the installed code)")  # fmt: skip
    args = ap.parse_args()
    if args.baseline and args.sample:
        side_by_side_sample(args.baseline, args.repeat, args.candidate)
        return
    if args.log:
        log = Path(args.log)
    else:
        log = Path(tempfile.gettempdir()) / "fuzzyslam_bench_paper.mcap"
        if not log.exists():
            subprocess.run(
                [sys.executable, "-m", "fuzzyslam", "simulate", "paper", "-o", str(log)],
                check=True,
                stdout=subprocess.DEVNULL,
            )
    if args.prefetch:
        side_by_side_prefetch(log.resolve(), args.repeat)
        return
    if args.baseline and args.calibration:
        side_by_side_calibration(log.resolve(), args.baseline, args.repeat, args.candidate)
        return
    if args.baseline:
        side_by_side_run(log.resolve(), args.baseline, args.repeat, args.candidate)
        return
    bench_log(log)
    bench_scaling()


if __name__ == "__main__":
    main()
