"""Benchmark on real building logs: maps from laser scans and sonar rings, lamp-less localisation.

Run: python benchmarks/bench_buildings.py [--data DIR] [--buildings NAME ...]
         [--ranges scan sonar] [--out DIR]

``DIR`` (default ``../shared/data/real``, or ``../../shared/data/real``) holds one
directory per building with ``log.mcap`` (/scan LaserScan, /sonar/sNN Range, /tf_static,
/odom with wheel errors) and ``truth.tum`` (the corrected poses); every such directory is
used unless ``--buildings`` names some.
For each building and each range sensor (``--ranges``, with the embedded config
``real_building_<ranges>.yaml``), through the ``fuzzyslam`` command, one JSON line with:

- ``map``: the FGM built from the truth poses (``fuzzyslam map --trajectory truth.tum``);
  its dominant wall direction (Hough line energy of the whole frozen map and the shared
  TLS fit of its lines, ``maps.hough.map_wall_direction``) against the one measured
  independently from the laser end points in world coordinates (truth poses, every
  beam, no evidence model): the end points binned in 5 cm cells, a cell hit by at least
  3 returns is wall (people and noise are not), and the same line estimator
  (``maps.hough.dominant_direction``) on those cells. Target |error| <= 0.5 deg. Also
  printed: the mode of the local directions of the scans' straight runs (principal axis
  of 9 consecutive end points, spread across below 2 cm, weighted by length; the peak of
  their 0.1-degree histogram refined by the mean within 1 deg), a second measure whose
  difference from the first shows how sharply a building's walls define one direction
  (the local directions spread over several degrees);
- ``dead_reckoning``: ``fuzzyslam run`` with no map (odometry alone);
- ``pose`` and ``heading``: ``fuzzyslam run --map FGM --fix pose|heading --fix-from 0``
  over the whole log from /odom; position error mean and max (m), heading error mean
  (deg) against truth at the estimate's stamps (truth lines that jump away and back,
  stray copies of the first pose in these conversions, dropped and counted as
  ``fuzzyslam evaluate`` drops them: ``evaluation.evaluate.read_truth``, the odometry
  glitch gate), and the real-time factor (log duration /
  wall time of the command, reading included). Targets: pose mean <= 0.3 m, max <= 1.0 m;
  heading mean <= 1 deg; pose >= 100x real time. For ``heading`` also ``fixes``: the
  fixes applied, their own error against truth (mean, median), and the share of the run
  more than 30 s after an applied fix (where the error comes from: the fixes or the
  drift between them).

With ``--figures DIR``: ``DIR/<building>_<ranges>.png``, the FGM with the true and the
localised (pose fixes) paths.

Timings share the machine with whatever else runs: compare side by side.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from fuzzyslam.config import load_config
from fuzzyslam.evaluation.evaluate import read_truth
from fuzzyslam.evaluation.metrics import interpolate_poses, pose_errors
from fuzzyslam.maps.hough import dominant_direction, map_wall_direction
from fuzzyslam.maps.mapio import load_fgm
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.tum import read_tum

ROOT = Path(__file__).resolve().parents[1]


def fuzzyslam(*args: str) -> dict:
    """Run one ``fuzzyslam`` command; its JSON summary and wall time."""
    env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1"}
    t0 = time.perf_counter()
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    out = subprocess.run(
        [sys.executable, "-m", "fuzzyslam", *args], capture_output=True, text=True, env=env
    )
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if out.returncode != 0:
        raise SystemExit(f"fuzzyslam {' '.join(args)} failed: {out.stderr.strip()}")
    summary = json.loads(out.stdout)
    summary["_wall"] = wall
    summary["_cpu"] = cpu
    return summary


def clean_truth(truth: Path) -> tuple[np.ndarray, np.ndarray, int]:
    """The truth's times and poses without its stray lines, and how many were dropped:
    the truth ``fuzzyslam evaluate`` uses (``read_truth``, which drops them with
    ``evaluation.core.drop_stray_truth``, the odometry glitch gate: the CARMEN
    conversions repeat the first pose now and then)."""
    tr = read_truth(truth, progress=False)
    return tr.t, tr.poses, int(tr.lines_dropped or 0)


def scan_end_points(log: Path, truth: Path) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Per /scan message taken at a pose the truth covers: the world x, y (M,) of its
    beams' end points in beam order, NaN where a beam has no valid return (out of its
    limits, or beyond 20 m)."""
    t_tr, p_tr, _ = clean_truth(truth)
    for m in LogReader(log).messages(["/scan"]):
        msg = m.msg
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        pose = interpolate_poses(t_tr, p_tr, [t])[0]
        if not np.all(np.isfinite(pose)):
            continue
        r = np.asarray(msg.ranges, dtype=float)
        a = msg.angle_min + np.arange(len(r)) * msg.angle_increment + pose[2]
        ok = np.isfinite(r) & (r >= msg.range_min) & (r < min(msg.range_max, 20.0))
        yield (np.where(ok, pose[0] + r * np.cos(a), np.nan),
               np.where(ok, pose[1] + r * np.sin(a), np.nan))  # fmt: skip


def laser_wall_direction(
    log: Path, truth: Path, near: float | None = None, window: int = 9
) -> float:
    """Dominant wall direction (rad, mod pi) of the laser end points in world coordinates
    (module docstring); with ``near``, the dominant one within 45 deg of it (the same
    family of walls as a direction measured otherwise: the two families of a building are
    not exactly at right angles)."""
    angles, weights = [], []
    for x, y in scan_end_points(log, truth):
        if len(x) < window:
            continue
        wx = np.lib.stride_tricks.sliding_window_view(x, window)
        wy = np.lib.stride_tricks.sliding_window_view(y, window)
        good = np.all(np.isfinite(wx), axis=1)
        wx, wy = wx[good], wy[good]
        if not len(wx):
            continue
        dx, dy = wx - wx.mean(1, keepdims=True), wy - wy.mean(1, keepdims=True)
        sxx, syy, sxy = (dx * dx).mean(1), (dy * dy).mean(1), (dx * dy).mean(1)
        # principal axis of each window, its spread across (smaller eigenvalue)
        half_tr, det = 0.5 * (sxx + syy), sxx * syy - sxy * sxy
        lam_small = half_tr - np.sqrt(np.maximum(half_tr**2 - det, 0.0))
        theta = 0.5 * np.arctan2(2 * sxy, sxx - syy)
        length = np.hypot(wx[:, -1] - wx[:, 0], wy[:, -1] - wy[:, 0])
        line = (np.sqrt(lam_small) < 0.02) & (length > 0.2)
        angles.append(theta[line])
        weights.append(length[line])
    th = np.mod(np.concatenate(angles), np.pi)
    w = np.concatenate(weights)
    hist, edges = np.histogram(th, bins=1800, range=(0, np.pi), weights=w)
    centres = 0.5 * (edges[:-1] + edges[1:])
    if near is not None:
        off = np.mod(centres - near + np.pi / 2, np.pi) - np.pi / 2
        hist = np.where(np.abs(off) <= np.pi / 4, hist, 0.0)
    peak = centres[np.argmax(hist)]
    d = np.mod(th - peak + np.pi / 2, np.pi) - np.pi / 2  # offsets in (-90, 90] deg
    close = np.abs(d) < math.radians(1.0)
    return float(np.mod(peak + np.average(d[close], weights=w[close]), np.pi))


def laser_line_direction(log: Path, truth: Path, cell: float = 0.05, min_hits: int = 3) -> float:
    """Dominant wall direction (rad, [0, pi)) of the laser end points in world
    coordinates (module docstring): cells of ``cell`` m hit by at least ``min_hits``
    returns, each a point at its returns' centroid, through the maps' line estimator."""
    pts = [(x[np.isfinite(x)], y[np.isfinite(y)]) for x, y in scan_end_points(log, truth)]
    x, y = np.concatenate([p[0] for p in pts]), np.concatenate([p[1] for p in pts])
    ix, iy = np.floor(x / cell).astype(np.int64), np.floor(y / cell).astype(np.int64)
    key = (ix - ix.min()) * (iy.max() - iy.min() + 1) + (iy - iy.min())
    _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    cx, cy = np.bincount(inv, weights=x) / cnt, np.bincount(inv, weights=y) / cnt
    wall = cnt >= min_hits
    params = load_config("real_building_scan.yaml").fgm
    wd = dominant_direction(cx[wall], cy[wall], np.ones(int(wall.sum())), params, rho_step=cell)
    return float(wd.angle)


def diff180_deg(a: float, b: float) -> float:
    """a - b in degrees, reduced to (-90, 90]."""
    return float(np.rad2deg(np.mod(a - b + np.pi / 2, np.pi) - np.pi / 2))


def errors(traj: Path, truth: Path) -> dict:
    """Position error mean/max (m) and heading error mean (deg) against truth."""
    t, est = read_tum(traj)
    t_tr, p_tr, dropped = clean_truth(truth)
    tru = interpolate_poses(t_tr, p_tr, t)
    ok = np.all(np.isfinite(tru), axis=1)
    e = pose_errors(est[ok], tru[ok])
    pos = np.hypot(e[:, 0], e[:, 1])
    return {
        "position_mean_m": round(float(pos.mean()), 3),
        "position_max_m": round(float(pos.max()), 3),
        "heading_mean_deg": round(float(np.rad2deg(np.abs(e[:, 2]).mean())), 3),
        "rows": int(ok.sum()),
        "truth_lines_dropped": dropped,
    }


def heading_fix_errors(run_dir: Path, truth: Path) -> dict:
    """The heading fixes of a ``--fix heading`` run (heading_fixes.csv) against truth:
    how many were applied, their measured heading's error (mean and median |error|,
    deg; the fixes' own quality), and the share of the trajectory's rows more than 30 s
    after the last applied fix (the drift between fixes)."""
    import csv

    with open(run_dir / "heading_fixes.csv", encoding="utf-8") as f:
        rows = [r for r in csv.DictReader(f) if r["accepted"] == "1"]
    t_tr, p_tr, _ = clean_truth(truth)
    t = np.array([float(r["t"]) for r in rows])
    meas = np.array([float(r["measured"]) for r in rows])
    tru = interpolate_poses(t_tr, p_tr, t)[:, 2] if len(t) else np.zeros(0)
    e = np.abs(np.rad2deg(np.mod(meas - tru + np.pi, 2 * np.pi) - np.pi))
    e = e[np.isfinite(e)]
    tt, _ = read_tum(run_dir / "trajectory.tum")
    last = np.searchsorted(t, tt, side="right") - 1
    since = np.where(last >= 0, tt - t[np.maximum(last, 0)], np.inf) if len(t) else np.inf
    return {
        "fixes_applied": len(rows),
        "fix_error_mean_deg": round(float(e.mean()), 3) if e.size else None,
        "fix_error_median_deg": round(float(np.median(e)), 3) if e.size else None,
        "share_30s_after_a_fix": round(float(np.mean(since > 30.0)), 3),
    }


def figure(path: Path, fgm, truth: Path, traj: Path, title: str) -> None:
    """The FGM (BetP(occupied)) with the true path and the localised one (PNG)."""
    from matplotlib.figure import Figure

    from fuzzyslam.figsave import BLACK, MIN_LW, ORANGE, PRINT_DPI, WIDE_W, save_png, styled

    @styled  # the figures' one style (fuzzyslam/figsave.py): a page's width, 8-9 pt text
    def draw() -> None:
        _, p_tr, _ = clean_truth(truth)
        _, est = read_tum(traj)
        fig = Figure(figsize=(WIDE_W, 0.75 * WIDE_W))
        ax = fig.add_subplot()
        ax.imshow(
            1.0 - fgm.pignistic_occupied(), origin="lower", extent=fgm.grid.extent,
            cmap="gray", vmin=0, vmax=1,
        )  # fmt: skip
        ax.plot(est[:, 0], est[:, 1], "-", color=ORANGE, lw=1.5 * MIN_LW,
                label="localised (pose fixes)")  # fmt: skip
        ax.plot(p_tr[:, 0], p_tr[:, 1], "--", color=BLACK, lw=MIN_LW, label="truth")  # on top
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(title, wrap=True)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
        save_png(fig, path, PRINT_DPI, tight=True)

    draw()


def bench_building(
    name: str, d: Path, ranges: list[str], out: Path, figures: Path | None = None
) -> list[dict]:
    log, truth = d / "log.mcap", d / "truth.tum"
    laser_all = laser_wall_direction(log, truth)
    laser_lines = laser_line_direction(log, truth)
    rows = []
    (out / name).mkdir(parents=True, exist_ok=True)
    fuzzyslam("run", str(log), "-o", str(out / name / "dr"))
    dr_err = errors(out / name / "dr" / "trajectory.tum", truth)
    for rs in ranges:
        config = f"real_building_{rs}.yaml"
        cfg = load_config(config)
        fgm_dir = out / name / f"fgm_{rs}"
        m = fuzzyslam(
            "map", str(log), "--trajectory", str(truth), "--config", config, "-o", str(fgm_dir)
        )
        fgm = load_fgm(fgm_dir / "fgm.npz").map
        wd = map_wall_direction(fgm, cfg.fgm)
        laser = laser_wall_direction(log, truth, near=wd.angle)
        row = {
            "building": name,
            "ranges": rs,
            "map": {
                "fgm_direction_deg": round(math.degrees(wd.angle), 3),
                "laser_direction_deg": round(math.degrees(laser_lines), 3),
                "error_deg": round(diff180_deg(wd.angle, laser_lines), 3),
                "laser_segments_mode_deg": round(math.degrees(laser), 3),
                "laser_segments_dominant_deg": round(math.degrees(laser_all), 3),
                "error_to_segments_mode_deg": round(diff180_deg(wd.angle, laser), 3),
                "references": len(m["references"]),
                "wall_seconds": round(m["_wall"], 2),
            },
            "dead_reckoning": dr_err,
        }
        for fix in ("pose", "heading"):
            rdir = out / name / f"{fix}_{rs}"
            s = fuzzyslam(
                "run", str(log), "--config", config, "--map", str(fgm_dir), "--fix", fix,
                "--fix-from", "0", "-o", str(rdir),
            )  # fmt: skip
            row[fix] = {
                **errors(rdir / "trajectory.tum", truth),
                "real_time_factor": round(s["log_duration_s"] / s["_wall"], 1),
                "real_time_factor_cpu": round(s["log_duration_s"] / s["_cpu"], 1),
                "cpu_ms_per_log_s": round(1e3 * s["_cpu"] / s["log_duration_s"], 2),
                "real_time_factor_in_process": s["real_time_factor"],
                "odometry_turn_check": s.get("odometry_turn_check"),
                "filter_health_reasons": s["filter_health"]["reasons"],
            }
            if fix == "heading":
                row[fix]["fixes"] = heading_fix_errors(rdir, truth)
        if figures is not None:
            p = row["pose"]
            traj = out / name / f"pose_{rs}" / "trajectory.tum"
            figure(
                figures / f"{name}_{rs}.png", fgm, truth, traj,
                f"{name}, FGM from --ranges {rs}; localised from /odom with pose fixes: "
                f"mean {p['position_mean_m']:.2f} m, max {p['position_max_m']:.2f} m",
            )  # fmt: skip
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=_default_data())
    ap.add_argument("--buildings", nargs="*", default=None)
    ap.add_argument("--ranges", nargs="*", default=["scan", "sonar"])
    ap.add_argument("--out", type=Path, default=None, help="keep the outputs here")
    ap.add_argument(
        "--figures", type=Path, default=None, help="write BUILDING_RANGES.png (FGM and paths) here"
    )
    a = ap.parse_args()
    if a.figures is not None:
        a.figures.mkdir(parents=True, exist_ok=True)
    names = a.buildings or sorted(
        p.name for p in a.data.iterdir() if (p / "truth.tum").is_file() and _has_scan(p)
    )
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = a.out or Path(tmp)
        for name in names:
            rows += bench_building(name, a.data / name, a.ranges, out, a.figures)
    print(table(rows))


def table(rows: list[dict]) -> str:
    """The rows as a Markdown table (targets in the header)."""
    lines = [
        "| building, ranges | map direction error (0.5 deg) | pose fixes mean / max "
        "(0.3 / 1.0 m) | heading fixes mean heading error (1 deg) | run --fix pose: real "
        "time (100x), wall / CPU | CPU ms per log-second | dead reckoning mean |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        p, h = r["pose"], r["heading"]
        lines.append(
            f"| {r['building']} {r['ranges']} | {r['map']['error_deg']:+.2f} deg "
            f"| {p['position_mean_m']:.2f} / {p['position_max_m']:.2f} m "
            f"| {h['heading_mean_deg']:.2f} deg "
            f"| {p['real_time_factor']:.0f}x / {p['real_time_factor_cpu']:.0f}x "
            f"| {p['cpu_ms_per_log_s']:.1f} | {r['dead_reckoning']['position_mean_m']:.2f} m |"
        )
    return "\n".join(lines)


def _default_data() -> Path:
    """``../shared/data/real`` from the project, or from the directory above it."""
    for up in ROOT.parents[:2]:
        if (up / "shared" / "data" / "real").is_dir():
            return up / "shared" / "data" / "real"
    return ROOT.parent / "shared" / "data" / "real"


def _has_scan(d: Path) -> bool:
    return (d / "log.mcap").is_file() and LogReader(d / "log.mcap").has("/scan")


if __name__ == "__main__":
    main()
