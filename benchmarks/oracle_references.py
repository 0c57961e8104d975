"""Phase C with oracle corridor references: how far can better references take C / A?

    python benchmarks/oracle_references.py REPRODUCE_DIR OUTDIR [--seeds 0 1 2 3 4]
        [--variants true,constant,lit] [--prior-deg 0.08] [--config paper.yaml]

REPRODUCE_DIR is a ``fuzzyslam reproduce --keep-logs`` output (its ``seedN/paper.mcap``,
``seedN/fgm``, ``seedN/C``, ``seedN/eval_C``): variant (a), the map's own references.
For each seed and variant the map directory is copied to ``OUTDIR/seedN/VARIANT/fgm``
with the reference angles of ``references.yaml`` replaced, and phase C is run and
evaluated again with it (the lines of the output's ``commands.sh``):

- ``true`` (b): the true axis of each reference's corridor (the map summary's
  ``reference_truth``: the nearest corridor of the simulated world, whose walls are
  parallel to its axis, ``sim/world.py``). The floor of any refinement toward the walls.
- ``constant`` (c): the map's angle minus the mean error of the accepted heading fixes
  of that corridor against the true heading (runs 5-6 of (a)'s C run; the fix is
  t_ref - t_local, so a reference off by d moves every fix by d). The best constant per
  corridor for these FLM measurements, the truth's own sensor bias included: the limit a
  reference estimated in the filter (one state per corridor) could converge to.
- ``lit`` (d): what the lamps can teach the references: the map's angle combined with
  the accepted fixes made where lamps pin the heading (a lamp update within 0.3 s) as
  measurements t_ref = fix + t_ref_map - theta_est (theta_est: (a)'s filter heading),
  prior sigma ``--prior-deg`` (the map references' rms error on the 5 paper seeds,
  0.08 deg), each fix of variance 2 (0.5 deg)^2 (``fixes.sigma_flm_deg``, windows sharing
  half their rings). Uses runs 5 and 6 both, so it is an optimistic stand-in for a
  causal estimate.

Per seed and variant it prints phase A's and C's ('after': runs 5-6) mean position error
(cm, the C run's evaluation) and their ratio, the mean over the dark stretches (no lamp
update for more than 2 s) and its share of C's mean, and C's mean absolute along-track
and cross-track error and heading error (against the true heading): a heading fix can
only correct the cross-track part.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import yaml

from fuzzyslam.se2 import interpolate_poses, wrap_angle, wrap_angle_period
from fuzzyslam.streams.tum import read_tum


def accepted_fixes(run: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times (n,), corridor ids (n,) and measured headings (n,) of a run's accepted fixes."""
    with open(run / "heading_fixes.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["accepted"] == "1"]
    t = np.array([float(r["t"]) for r in rows])
    c = np.array([int(r["corridor"]) for r in rows])
    return t, c, np.array([float(r["measured"]) for r in rows])


def lamp_times(run: Path) -> np.ndarray:
    """Sorted times (n,) of a run's accepted lamp updates (updates.csv)."""
    with open(run / "updates.csv", newline="") as f:
        t = [
            float(r["t"]) for r in csv.DictReader(f) if r["kind"] == "lamp" and r["accepted"] == "1"
        ]
    return np.sort(np.array(t))


def near(t: np.ndarray, events: np.ndarray, within: float) -> np.ndarray:
    """Whether each of ``t`` (n,) has one of the sorted ``events`` within ``within`` s."""
    i = np.searchsorted(events, t)
    lo = events[np.clip(i - 1, 0, len(events) - 1)]
    hi = events[np.clip(i, 0, len(events) - 1)]
    return np.minimum(np.abs(t - lo), np.abs(hi - t)) <= within


def heading_at(tum: Path, t: np.ndarray) -> np.ndarray:
    """A TUM trajectory's heading (n,) interpolated at ``t``."""
    tt, poses = read_tum(tum)
    return interpolate_poses(tt, poses, t, outside="hold")[:, 2]


def fix_errors(run: Path, truth: Path) -> tuple[np.ndarray, np.ndarray]:
    """Corridor ids (n,) and errors (n, rad, mod pi) of a run's accepted fixes."""
    t, c, m = accepted_fixes(run)
    return c, wrap_angle_period(m - heading_at(truth, t), np.pi)


def new_angles(variant: str, fgm: Path, run: Path, truth: Path, prior_deg: float) -> dict:
    """Reference id -> angle (rad) of a variant."""
    doc = yaml.safe_load((fgm / "references.yaml").read_text())
    angles = {r["id"]: float(r["angle"]) for r in doc["references"]}
    if variant == "true":
        truth_rows = json.loads((fgm / "summary.json").read_text())["reference_truth"]
        return {e["id"]: float(np.deg2rad(e["true_axis_deg"])) for e in truth_rows}
    if variant == "constant":
        c, e = fix_errors(run, truth)
        return {k: a - (e[c == k].mean() if np.any(c == k) else 0.0) for k, a in angles.items()}
    # lit: prior N(t_map, sp^2); fixes z_i = t_map - v_i, v_i = fix - theta_est, var r
    t, c, m = accepted_fixes(run)
    lit = near(t, lamp_times(run), 0.3)
    v = wrap_angle_period(m - heading_at(run / "trajectory.tum", t), np.pi)
    sp2, r = np.deg2rad(prior_deg) ** 2, 2.0 * np.deg2rad(0.5) ** 2
    out = {}
    for k, a in angles.items():
        sel = lit & (c == k)
        out[k] = a - (v[sel].sum() / r) / (1.0 / sp2 + sel.sum() / r)
    return out


def write_variant(fgm: Path, out: Path, angles: dict) -> None:
    """Copy the map directory ``fgm`` to ``out`` with the reference angles replaced."""
    shutil.copytree(fgm, out, dirs_exist_ok=True)
    doc = yaml.safe_load((fgm / "references.yaml").read_text())
    for r in doc["references"]:
        r["angle"] = float(angles[r["id"]])
        r["angle_deg"] = float(np.rad2deg(r["angle"]))
    (out / "references.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))


def figures(run: Path, ev: Path, truth: Path) -> dict:
    """Phase A's and C's mean position error, C's dark-stretch mean and share, along- and
    cross-track and heading error (cm, deg) of a C run and its evaluation."""
    ph = json.loads((ev / "metrics.json").read_text())["phases"]
    t0, t1 = ph["after"]["t0"], ph["after"]["t1"]
    t, est = read_tum(run / "trajectory.tum")
    keep = (t >= t0) & (t <= t1)
    t, est = t[keep], est[keep]
    tt, tp = read_tum(truth)
    tru = interpolate_poses(tt, tp, t, outside="hold")
    d = est[:, :2] - tru[:, :2]
    c, s = np.cos(tru[:, 2]), np.sin(tru[:, 2])
    along, cross = c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]
    err = np.hypot(d[:, 0], d[:, 1])
    lamps = lamp_times(run)
    lamps = lamps[lamps >= t0]
    dark = np.zeros(len(t), bool)
    for g in np.nonzero(np.diff(lamps) > 2.0)[0]:
        dark |= (t > lamps[g]) & (t < lamps[g + 1])
    return {
        "A": 100 * ph["A"]["position_m"]["mean"],
        "C": 100 * ph["after"]["position_m"]["mean"],
        "dark": 100 * err[dark].mean(),
        "dark_share": err[dark].sum() / err.sum(),
        "along": 100 * np.abs(along).mean(),
        "cross": 100 * np.abs(cross).mean(),
        "head": float(np.rad2deg(np.abs(wrap_angle(est[:, 2] - tru[:, 2])).mean())),
    }


def line(seed: int, name: str, f: dict) -> str:
    return (
        f"{seed} | {name} | {f['A']:.2f} | {f['C']:.2f} | {f['C'] / f['A']:.1f} | "
        f"{f['dark']:.2f} ({100 * f['dark_share']:.0f} %) | {f['along']:.2f} | "
        f"{f['cross']:.2f} | {f['head']:.3f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("base", type=Path)
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--variants", default="true,constant,lit")
    ap.add_argument("--prior-deg", type=float, default=0.08)
    ap.add_argument("--config", default="paper.yaml", help="run's config (run ignores robot.*)")
    args = ap.parse_args()
    exe = str(Path(sys.executable).with_name("fuzzyslam"))
    head = "seed | references | A cm | C cm | C/A | dark cm (share of C) | along cm | cross cm"
    print(head + " | heading deg")
    for s in args.seeds:
        src = args.base / f"seed{s}"
        truth = src / "eval_C" / "truth.tum"
        print(line(s, "map (a)", figures(src / "C", src / "eval_C", truth)), flush=True)
        for v in args.variants.split(","):
            out = args.outdir / f"seed{s}" / v
            angles = new_angles(v, src / "fgm", src / "C", truth, args.prior_deg)
            write_variant(src / "fgm", out / "fgm", angles)
            log = str(src / "paper.mcap")
            run = [exe, "run", log, "-o", str(out / "C"), "--config", args.config]
            run += ["--map", str(out / "fgm"), "--fix", "heading"]
            subprocess.run(run, check=True, stdout=subprocess.DEVNULL)
            ev = [exe, "evaluate", log, str(out / "C"), "-o", str(out / "eval_C")]
            ev += ["--map", str(out / "fgm"), "--label", f"C: {v} references"]
            subprocess.run(ev, check=True, stdout=subprocess.DEVNULL)
            print(line(s, v, figures(out / "C", out / "eval_C", truth)), flush=True)


if __name__ == "__main__":
    main()
