"""Real landmark logs: EKF-SLAM with ``--config real_detections.yaml`` and nothing else.

    python benchmarks/bench_real_landmarks.py [DATA_DIR] [--adapt-noise]

DATA_DIR holds one folder per log with ``log.mcap``, ``truth.tum`` and
``landmarks_truth.yaml`` (default: ../shared/data/real beside the repository, the UTIAS
MRCLAM logs; skipped when absent). For each log it runs ``fuzzyslam run`` and
``fuzzyslam evaluate --landmarks-truth`` and prints: APE RMSE after a rigid 2-D alignment
(SLAM and dead reckoning), true landmarks with an estimate within 0.5 m, estimates left
over after the one-to-one matching, NEES mean (3 dof, against the aligned truth),
time with NEES above 100, what filter_health says, the real-time factor (log duration over
wall time, as the summary gives it, and over the process's CPU time: the figure to read
on a loaded machine), the odometry latency the bearings imply, and the odometry checks
of filter_health: the estimate's turns and displacements over the odometry's (``*`` when
flagged, ``c`` when the distances are confounded by the turns), with the displacements'
ratio the motion capture gives (truth over dead reckoning, the same windows and fit:
what the estimate's ratio should be). ``log_variants.py --odometry-scale`` makes the
logs with their odometry rescaled that the README's figures for those checks come from.

With ``--baseline REV`` it instead times ``fuzzyslam run`` of the old code (git revision
REV) and of this code side by side on each log, alternating, ``--repeat`` times each
(benchmarks/sidebyside.py): CPU and wall medians, the real-time factors (log duration
over CPU and over wall time, target >= 200x) and whether the outputs are byte-identical
(summary.json without its timing fields).

    python benchmarks/bench_real_landmarks.py [DATA_DIR] --baseline main --repeat 3
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np


def fuzzyslam(*args) -> dict:
    res = subprocess.run(
        [sys.executable, "-m", "fuzzyslam", *map(str, args)], capture_output=True, text=True
    )
    if res.returncode != 0:
        raise SystemExit(f"fuzzyslam {' '.join(map(str, args))}: {res.stderr.strip()}")
    return json.loads(res.stdout)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
    ap.add_argument("data", nargs="?", default=str(default))
    ap.add_argument("--adapt-noise", action="store_true")
    ap.add_argument("--baseline", metavar="REV", default=None)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--config", default="real_detections.yaml",
                    help="the config (a name or a YAML path; not with --baseline)")
    a = ap.parse_args()
    logs = sorted(p for p in Path(a.data).glob("*") if (p / "landmarks_truth.yaml").is_file())
    if not logs:
        print(f"no landmark logs under {a.data}: skipped")
        return
    if a.baseline:
        side_by_side_runs(logs, a.baseline, a.repeat)
        return
    print(f"{'log':16s} {'APE m':>6s} {'DR m':>6s} {'found':>5s} {'left':>4s} {'NEES':>6s} "
          f"{'NEES>100 s':>10s} {'diverged':>8s} {'RTF':>6s} {'CPU RTF':>7s} {'lag s':>6s} "
          f"{'turn k':>7s} {'dist k':>7s} {'true':>6s}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        for log in logs:
            run = Path(tmp) / log.name
            extra = ["--adapt-noise"] if a.adapt_noise else []
            c0 = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime
            s = fuzzyslam("run", log / "log.mcap", "--config", a.config, "-o", run, *extra)
            cpu = resource.getrusage(resource.RUSAGE_CHILDREN).ru_utime - c0
            lag = (s.get("odometry_delay_estimate") or {}).get("delay_s")
            ev = Path(tmp) / f"{log.name}_ev"
            h = fuzzyslam("evaluate", log / "truth.tum", run, "--landmarks-truth",
                          log / "landmarks_truth.yaml", "-o", ev)
            m = json.loads((ev / "metrics.json").read_text())
            dr = m["odometry"]["position_m"]
            cov = np.loadtxt(run / "covariance.csv", delimiter=",", skiprows=1, ndmin=2)
            nees_t = m["phases"]["overall"]["nees"]
            over = nees_t.get("frac_above_100", None)
            print(f"{log.name:16s} {h['ape_aligned_rmse_m']:6.3f} {dr['rmse']:6.3f} "
                  f"{h['lamps_true_within_0.5_m']:5d} {h['lamps_left_over']:4d} "
                  f"{h['nees_mean']:6.2f} "
                  f"{'' if over is None else f'{over * (cov[-1, 0] - cov[0, 0]):.0f}':>10s} "
                  f"{s['filter_health']['diverged']!s:>8s} {s['real_time_factor']:6.1f} "
                  f"{s['log_duration_s'] / cpu:7.1f} {'' if lag is None else f'{lag:.3f}':>6s} "
                  f"{_check(s['odometry_turn_check']):>7s} "
                  f"{_check(s['odometry_distance_check']):>7s} "
                  f"{_true_distance_ratio(run, log / 'truth.tum'):6.3f}")  # fmt: skip


def _check(c: dict | None) -> str:
    """An odometry check's ratio, ``*`` when flagged, ``c`` when confounded."""
    if c is None:
        return "-"
    mark = "*" if c["flagged"] else "c" if c.get("confounded_by_turns") else ""
    return f"{c['ratio']:.3f}{mark}"


def _true_distance_ratio(run: Path, truth: Path) -> float:
    """The ratio of the truth's displacements to the dead reckoning's (odometry.tum) over
    the distance check's windows and fit (``turn_check.distance_ratio``)."""
    from fuzzyslam.slam.turn_check import distance_ratio
    from fuzzyslam.streams.tum import read_tum

    to, po = read_tum(run / "odometry.tum")[:2]
    tt, pt = read_tum(truth)[:2]
    inside = (to >= tt[0]) & (to <= tt[-1])
    xy = np.column_stack([np.interp(to, tt, pt[:, k]) for k in (0, 1)])
    c = distance_ratio(to[inside], xy[inside], po[inside, :2])
    return float("nan") if c is None else c.ratio


def side_by_side_runs(logs: list[Path], rev: str, repeat: int) -> None:
    """Old (``rev``) and new ``fuzzyslam run --config real_detections.yaml``, alternately."""
    sys.path.insert(0, str(Path(__file__).parent))
    from sidebyside import export_revision, load, same_outputs, side_by_side

    from fuzzyslam.streams.reader import LogReader

    src = export_revision(rev)
    work = Path(tempfile.mkdtemp(prefix="bench_real."))
    for log in logs:
        reader = LogReader(log / "log.mcap")
        duration = reader.end - reader.start
        outs = {v: work / f"{log.name}_{v}" for v in ("old", "new")}
        before = load()
        res = side_by_side(lambda v, outs=outs, log=log: [
            "run", str(log / "log.mcap"), "--config", "real_detections.yaml", "-o",
            str(outs[v])], src, repeat)  # fmt: skip
        for v in ("old", "new"):
            res[v]["real_time_factor_cpu"] = round(duration / res[v]["cpu_median_s"])
            res[v]["real_time_factor_wall"] = round(duration / res[v]["wall_median_s"])
        same = same_outputs(outs["old"], outs["new"])["identical"]
        print(json.dumps({"run": log.name, "log_s": round(duration, 1), "baseline": rev,
                          "repeat": repeat, **res, "target_real_time_factor": 200,
                          "outputs_byte_identical": same,
                          "load_before": before, "load_after": load()}, indent=2))  # fmt: skip


if __name__ == "__main__":
    main()
