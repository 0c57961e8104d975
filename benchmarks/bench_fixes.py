"""Benchmark of the fixes stage: cost per ring and accuracy on synthetic worlds.

Run: python benchmarks/bench_fixes.py [--n 40]

Worlds, ray-cast sonar rings and clean ("ideal", laser-like) FLMs come from the
fixes tests' helpers (tests/test_fixes.py); FLMs are built by the maps stage's
``build_flm``, wall directions by its ``flm_wall_direction``, FGMs by its ``FgmBuilder``.

Prints, for each part, one line of JSON:
- cost: ms per pose match (narrow window: sigma 3 cm / 0.5 deg; wide: 10 cm / 2 deg),
  per heading decision (Hough + decide), per change detection, per FLM build; and the
  implied real-time factor at 4 rings/s for pose fixes on every ring;
- accuracy: heading-fix error (deg) in a straight corridor, sonar and clean FLMs; pose
  match position / heading error and mean NEES (3 dof, consistency: about 3); wall direction
  of one ring vs the FLM of the last k rings placed by odometry (``fixes.flm_rings``), and
  the cost of one multi-ring fix.
- with ``--run`` (or ``--log LOG --map FGMDIR``): the real-time factor of the whole
  ``fuzzyslam run`` (log duration / wall time, reading the log included) with
  ``--fix none|heading|pose`` on a paper.yaml log (simulated, run and mapped first into a
  temporary directory when no log is given). Target: pose >= 100x.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import test_fixes as tf

from fuzzyslam.fixes.changes import detect_changes, free_space
from fuzzyslam.fixes.heading import decide_heading_fix
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.pose_match import PoseMatcher
from fuzzyslam.maps.flm import RecentRings
from fuzzyslam.maps.grid import Grid
from fuzzyslam.maps.hough import flm_wall_direction
from fuzzyslam.se2 import rot, wrap_angle

DEG = math.pi / 180


def room_world():
    walls = tf.polygon_walls(tf.L_ROOM)
    poly = np.array(tf.L_ROOM, float)
    xs, ys = np.meshgrid(np.arange(0.5, 6.0, 0.5), np.arange(0.5, 5.0, 0.5))
    pts = np.stack([xs.ravel(), ys.ravel()], axis=1)
    pts = pts[tf.points_in_polygon(pts, poly)]
    poses = np.concatenate([np.column_stack([pts, np.full(len(pts), h)]) for h in (0.0, 0.4)])
    return walls, tf.build_fgm(walls, poses, Grid.covering(-1, -1, 7, 6, 0.1))


def random_room_poses(walls, n, rng):
    out = []
    while len(out) < n:
        p = np.array([rng.uniform(0.5, 5.5), rng.uniform(0.5, 4.5), rng.uniform(-3, 3)])
        if tf.in_l_room(p[None, :2])[0] and tf.seg_distance(p[None, :2], walls)[0] > 0.4:
            out.append(p)
    return out


def timeit(fn, reps):
    t0 = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t0) / reps * 1e3


def run_rtf(log: Path | None, fgm_dir: Path | None, config: str, seed: int) -> dict:
    """Real-time factor of ``run`` with each fix mode (best of 2 runs each)."""
    import tempfile

    from fuzzyslam.config import load_config
    from fuzzyslam.fixes.aids import make_aids
    from fuzzyslam.maps.mapio import log_identity
    from fuzzyslam.sim.record import simulate_to_mcap
    from fuzzyslam.slam.stage import run_stage
    from fuzzyslam.streams.logmeta import read_world
    from fuzzyslam.streams.reader import LogReader

    cfg = load_config(config, seed)
    tmp = Path(tempfile.mkdtemp(prefix="bench_fixes_"))
    if log is None:
        from click.testing import CliRunner

        from fuzzyslam.cli import _register, cli

        _register()
        log = tmp / "log.mcap"
        simulate_to_mcap(cfg, log)
        run_stage(log, tmp / "A", cfg)
        res = CliRunner().invoke(
            cli, ["map", str(log), "--trajectory", str(tmp / "A" / "trajectory.tum"),
                  "-o", str(tmp / "fgm")]
        )  # fmt: skip
        assert res.exit_code == 0, res.output
        fgm_dir = tmp / "fgm"
    reader = LogReader(log)
    world = read_world(reader)
    lid = log_identity(world.to_dict() if world else None, reader.fingerprint())
    out = {"log": str(log)}
    for mode in ("none", "heading", "pose"):
        best = 0.0
        for k in range(2):
            aids = make_aids(fgm_dir, mode, cfg, expect_log_id=lid)
            summ = run_stage(log, tmp / f"{mode}{k}", cfg, aids)
            best = max(best, summ["real_time_factor"])
        out[f"rtf_{mode}"] = best
        out["log_duration_s"] = summ["log_duration_s"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=40, help="random poses per figure")
    ap.add_argument("--run", action="store_true", help="also time 'run' on a full log")
    ap.add_argument("--log", type=Path, default=None, help="log for --run (else simulated)")
    ap.add_argument("--map", type=Path, default=None, help="frozen map dir of --log")
    ap.add_argument("--config", default="paper.yaml", help="config of the simulated log")
    args = ap.parse_args()
    if args.run or args.log is not None:
        print(json.dumps({"run_real_time_factor": run_rtf(args.log, args.map, args.config, 0)}))
    rng = np.random.default_rng(0)
    params = FixParams()
    walls, fgm = room_world()
    t0 = time.perf_counter()
    pm = PoseMatcher(fgm, params)
    init_ms = (time.perf_counter() - t0) * 1e3
    poses = random_room_poses(walls, args.n, rng)
    flms = [tf.flm_at(p, walls) for p in poses]
    ms_flm = timeit(lambda: tf.flm_at(poses[0], walls), 50)

    # --- cost ---
    cost = {"fgm_cells": int(np.prod(fgm.grid.shape)), "matcher_init_ms": round(init_ms, 2)}
    for name, sig in (("narrow", (0.03, 0.5)), ("wide", (0.10, 2.0))):
        cov = np.diag([sig[0] ** 2, sig[0] ** 2, (sig[1] * DEG) ** 2])
        times = []
        for p, flm in zip(poses, flms, strict=True):
            pred = p + np.array([*rng.normal(0, sig[0], 2), rng.normal(0, sig[1] * DEG)])
            times.append(timeit(lambda flm=flm, pred=pred, cov=cov: pm.match(flm, pred, cov), 5))
        cost[f"pose_match_{name}_ms_mean"] = round(float(np.mean(times)), 3)
        cost[f"pose_match_{name}_ms_median"] = round(float(np.median(times)), 3)
    angle = 0.3
    cwalls = tf.corridor_walls(angle)
    ref = tf.corridor_ref(angle)
    cflm = tf.flm_at([0.0, 0.0, angle + 0.1], cwalls)
    cov = np.diag([1e-3, 1e-3, (1 * DEG) ** 2])

    def heading_once():
        w = flm_wall_direction(cflm, tf.MP)
        decide_heading_fix(0.0, w, [ref], np.array([0, 0, angle + 0.1]), cov, params)

    cost["heading_decision_ms"] = round(timeit(heading_once, 200), 3)
    free = free_space(fgm, params.change_erode_cells)
    cost["change_detection_ms"] = round(
        timeit(
            lambda: detect_changes(
                0.0,
                flms[0],
                poses[0],
                fgm.grid,
                free,
                params.change_min_conflict,
                params.change_min_cells,
            ),
            200,
        ),
        3,
    )
    cost["flm_build_plus_raycast_ms"] = round(ms_flm, 3)
    per_ring = cost["pose_match_narrow_ms_mean"] + cost["change_detection_ms"]
    cost["rtf_pose_fixes_alone_at_4Hz"] = round(1000.0 / (4 * per_ring), 1)
    print(json.dumps({"cost": cost}))

    # --- heading accuracy in a straight corridor ---
    acc = {}
    for kind, make in (("sonar", tf.flm_at), ("ideal", tf.ideal_flm)):
        errs, reasons = tf._corridor_heading_errors(make, args.n, 7)
        acc[f"heading_{kind}_ok_fraction"] = round(reasons.count("ok") / len(reasons), 3)
        if len(errs):
            acc[f"heading_{kind}_err_mean_deg"] = round(float(np.mean(errs)), 3)
            acc[f"heading_{kind}_err_std_deg"] = round(float(np.std(errs)), 3)
    # multi-ring FLM (issue 5): wall direction of the newest ring vs the last k rings placed
    # by odometry, weaving along the corridor with 1 % range noise; and the cost of one
    # multi-ring FLM + Hough + tangent refinement (one fix every k rings)
    for k in sorted({8, params.flm_rings}):
        single, multi = tf._window_heading_errors(7, args.n, k)
        acc[f"flm_rings_{k}_single_err_mean_deg"] = round(float(np.mean(single)), 3)
        acc[f"flm_rings_{k}_multi_err_mean_deg"] = round(float(np.mean(multi)), 3)
        acc[f"flm_rings_{k}_multi_err_std_deg"] = round(float(np.std(multi)), 3)
        recent = RecentRings(k, 100.0)
        for j in range(k):
            pose = np.array([*(rot(angle) @ [0.08 * j, 0.1]), angle + 0.05])
            recent.push(float(j), pose, tf.sonar_ranges(pose, cwalls, rng), tf.MAXR, tf.FOV)
        ms = timeit(lambda recent=recent: flm_wall_direction(recent.flm(tf.MOUNTS, tf.MP)), 20)
        acc[f"flm_rings_{k}_fix_ms"] = round(ms, 2)
    print(json.dumps({"heading_accuracy": acc}))

    # --- pose accuracy and consistency in the L room (the score surface itself: no
    # inflation for the correlation of successive rings) ---
    pm = PoseMatcher(fgm, FixParams(pose_cov_scale=1.0))
    out = {}
    for kind in ("sonar", "ideal"):
        errs, nees, ok = [], [], 0
        for p, flm in zip(poses, flms, strict=True):
            f = flm if kind == "sonar" else tf.ideal_flm(p, walls, tf.in_l_room)
            pred = p + np.array([*rng.normal(0, 0.08, 2), rng.normal(0, 1.5 * DEG)])
            m = pm.match(f, pred, np.diag([0.1**2, 0.1**2, (2 * DEG) ** 2]))
            if not m.ok:
                continue
            ok += 1
            e = m.pose - p
            e[2] = wrap_angle(e[2])
            errs.append([np.hypot(*e[:2]), abs(e[2]) / DEG, m.degenerate])
            nees.append(float(e @ np.linalg.solve(m.cov, e)))
        a = np.array(errs)
        out[kind] = {
            "ok_fraction": round(ok / len(poses), 3),
            "pos_err_mean_m": round(float(a[:, 0].mean()), 4),
            "pos_err_max_m": round(float(a[:, 0].max()), 4),
            "heading_err_mean_deg": round(float(a[:, 1].mean()), 3),
            "heading_free_fraction": round(float(np.mean(a[:, 2] > 0)), 3),
            "nees_mean": round(float(np.mean(nees)), 3),
        }
    # corridor: the covariance along / across the axis
    along = np.arange(-8, 8.01, 0.4)
    path = np.column_stack([along * math.cos(angle), along * math.sin(angle), 0 * along + angle])
    cwalls_long = tf.corridor_walls(angle, half_length=12.0)
    cfgm = tf.build_fgm(cwalls_long, path, Grid.covering(-11, -5, 11, 5, 0.1))
    cpm = PoseMatcher(cfgm, params)
    true = np.array([*(rot(angle) @ [1.0, 0.2]), angle + 0.1])
    m = cpm.match(
        tf.flm_at(true, cwalls),
        true + np.array([0.1, -0.1, 1.5 * DEG]),
        np.diag([0.01, 0.01, (2 * DEG) ** 2]),
    )
    ev = np.sqrt(np.linalg.eigvalsh(m.cov[:2, :2]))
    out["corridor_sonar"] = {"ok": m.ok, "sigma_across_m": round(float(ev[0]), 4),
                             "sigma_along_m": round(float(ev[1]), 1)}  # fmt: skip
    # drives with pose fixes only (toy 3-state EKF, no lamps), default parameters
    starts = [[1.0, 1.0, 0.2], [0.8, 4.2, -1.5], [5.5, 1.8, math.pi], [1.5, 0.6, 0.0]]
    drives = [tf._drive_with_pose_fixes(fgm, walls, s0, "sonar") for s0 in starts]
    out["drives_sonar"] = {
        "final_pos_err_m": [round(float(np.hypot(*e[:2])), 3) for e, _, _ in drives],
        "final_heading_err_deg": [round(abs(float(e[2])) / DEG, 2) for e, _, _ in drives],
        "mean_nees_after_10_rings": round(float(np.mean([n[10:].mean() for _, n, _ in drives])), 2),
    }
    print(json.dumps({"pose_accuracy": out}))


if __name__ == "__main__":
    main()
