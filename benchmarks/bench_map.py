"""Benchmark of the map stage: fusion speed, four-run FGM time, reference and FLM accuracy.

Usage::

    python benchmarks/bench_map.py [LOG.mcap [TRAJECTORY.tum]]

Without LOG it simulates the paper scenario into a temporary directory. Without a
trajectory the log's ground truth is used. Prints one JSON object:

- ``fusion``: cell updates (reading x cell evidence terms) per second of FgmBuilder.add_rings
  (batches of 64 rings, best of 3) on the rings up to the freeze, and the fusion time of
  the whole FGM (the machine's load matters: compare figures taken together);
- ``stage``: wall time of the map stage without figures (log decoding included);
- ``references``: each corridor's reference angle error against the true axis (deg);
- ``wall_quality``: precision/recall of wall cells within one cell of the true walls;
- ``flm``: time per FLM + Hough, and the heading error of theta = axis - t_local (mod pi)
  against the true heading, over every ring inside a corridor (1.5 m from its ends, 0.5 m
  from its centre line), rings flagged ambiguous left out: ``hough`` (the paper's peak
  alone), ``tangent`` (refined by the tangent-line fit, the default), and
  ``tangent_8_rings_odometry`` (FLM of the last 8 rings, ``build_flm_rings``, placed by
  the log's dead reckoning /odom).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from fuzzyslam.config import load_config
from fuzzyslam.maps.build import MapOptions, build_map, read_rings
from fuzzyslam.maps.fgm import FgmBuilder
from fuzzyslam.maps.flm import build_flm, build_flm_rings
from fuzzyslam.maps.hough import flm_wall_direction
from fuzzyslam.se2 import between, interpolate_poses, wrap_angle_period
from fuzzyslam.streams.logmeta import read_scenario, read_world
from fuzzyslam.streams.messages import pose_of
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.tum import read_tum, write_tum


def truth_tum(log: Path, out: Path) -> Path:
    t, p = [], []
    for m in LogReader(log).messages(["/ground_truth/odom"]):
        t.append(m.t)
        p.append(pose_of(m.msg.pose.pose))
    write_tum(out, np.array(t), np.array(p))
    return out


def odom_tum(log: Path) -> tuple[np.ndarray, np.ndarray]:
    t, p = [], []
    for m in LogReader(log).messages(["/odom"]):
        t.append(m.t)
        p.append(pose_of(m.msg.pose.pose))
    return np.array(t), np.array(p)


def main() -> None:
    tmp = Path(tempfile.mkdtemp(prefix="bench_map."))
    if len(sys.argv) > 1:
        log = Path(sys.argv[1])
    else:
        log = tmp / "paper.mcap"
        subprocess.run(
            [sys.executable, "-m", "fuzzyslam", "simulate", "paper", "-o", str(log)],
            check=True,
            stdout=subprocess.DEVNULL,
        )
    tum = Path(sys.argv[2]) if len(sys.argv) > 2 else truth_tum(log, tmp / "truth.tum")
    cfg = load_config(None)
    params = cfg.fgm
    reader = LogReader(log)
    scenario = read_scenario(reader)
    world = read_world(reader)
    t_end = scenario.run_end_time(params.freeze_run) if scenario else reader.end
    times, ranges, rmax, fov, mounts, *_ = read_rings(reader, cfg, t_end)
    t, p = read_tum(tum)
    poses = interpolate_poses(t, p, times, outside="hold")

    best = np.inf
    for _ in range(3):
        b = FgmBuilder.for_path(poses[:, :2], params)
        t0 = time.perf_counter()
        for k in range(0, len(times), 64):
            b.add_rings(poses[k : k + 64], ranges[k : k + 64], rmax[k : k + 64], fov, mounts)
        best = min(best, time.perf_counter() - t0)
    fusion = {
        "rings": len(times),
        "cell_updates": b.cell_updates,
        "seconds": best,
        "cell_updates_per_second": b.cell_updates / best,
        "rings_per_second": len(times) / best,
    }

    t0 = time.perf_counter()
    s = build_map(log, tum, tmp / "fgm", cfg, MapOptions(figures=False))
    stage = {"seconds_without_figures": time.perf_counter() - t0}

    # FLM heading error in corridors: measured heading = axis - t_local, mod pi
    truth = interpolate_poses(*read_tum(truth_tum(log, tmp / "t2.tum")), times, outside="hold")
    odom = interpolate_poses(*odom_tum(log), times, outside="hold")
    hough_only = dataclasses.replace(params, flm_refine="hough")
    errs: dict[str, list[float]] = {"hough": [], "tangent": [], "tangent_8_rings_odometry": []}
    amb = dict.fromkeys(errs, 0)
    dt: dict[str, list[float]] = {k: [] for k in errs}
    for k in range(len(times)):
        pose = truth[k]
        cor = None
        for c in world.corridors if world else []:
            a, bb = np.asarray(c.a), np.asarray(c.b)
            d = (bb - a) / np.linalg.norm(bb - a)
            u = (pose[:2] - a) @ d
            if 1.5 < u < np.linalg.norm(bb - a) - 1.5 and abs((pose[:2] - a) @ [-d[1], d[0]]) < 0.5:
                cor = c
        if cor is None:
            continue
        sl = slice(max(k - 7, 0), k + 1)  # 8 rings (2 s), placed by dead reckoning
        rel = between(odom[k], odom[sl])
        for name in errs:
            t1 = time.perf_counter()
            if name == "tangent_8_rings_odometry":
                flm = build_flm_rings(rel, ranges[sl], rmax[sl], fov, mounts, params)
            else:
                flm = build_flm(ranges[k], rmax[k], fov, mounts, params)
            wd = flm_wall_direction(flm, hough_only if name == "hough" else params)
            dt[name].append(time.perf_counter() - t1)
            if wd.ambiguous or not np.isfinite(wd.angle):
                amb[name] += 1
                continue
            errs[name].append(np.rad2deg(wrap_angle_period(cor.axis - wd.angle - pose[2], np.pi)))
    flm = {}
    for name, ev in errs.items():
        e = np.array(ev)
        flm[name] = {
            "rings": len(dt[name]),
            "ms_per_flm_and_hough": 1e3 * float(np.mean(dt[name])) if dt[name] else None,
            "ambiguous": amb[name],
            "heading_error_mean_abs_deg": float(np.mean(np.abs(e))) if len(e) else None,
            "heading_error_median_abs_deg": float(np.median(np.abs(e))) if len(e) else None,
            "heading_error_bias_deg": float(np.mean(e)) if len(e) else None,
            "heading_error_std_deg": float(np.std(e)) if len(e) else None,
        }
    print(
        json.dumps(
            {
                "log": str(log),
                "trajectory": str(tum),
                "fusion": fusion,
                "stage": stage,
                "references": s["reference_truth"],
                "wall_quality": s["wall_quality"],
                "flm": flm,
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
