"""Odometry self-calibration against the simulator's truth, per seed of a reproduce output.

    python benchmarks/calibration_vs_truth.py REPRODUCE_DIR [--config paper.yaml]

For each ``seedN`` it reads the calibration of the lamps-only run (``AB/calibration.yaml``,
the end of run 6), of the map (``fgm/calibration.yaml``, the freeze time: what phases C
and D start from) and of the C and D runs, and prints each factor with its 2-sigma bound
against the config's ``robot.left_scale``, ``right_scale``, ``base_scale`` (the
simulator's true wheels, ``slam.calibration.true_factors``), its error in sigmas
(``errors_in_sigma``, as reproduce's table has it for the map, C and D) and whether all
three are within 2 sigma (docs/models.md sec. 4b).

Then, from the evaluations (``eval_AB``, ``eval_C``, ``eval_D``), the issue-18 figures per
seed: phase A's mean position error, phase C's mean and its ratio to A, phase D's max x
and y error (cm), and where phase C's error comes from: the same runs 5-6 in the map's
frame (the rigid SE(2) that takes runs 1-4 of the C estimate onto the truth, applied to
runs 5-6). A phase-C error that the map's frame takes away is the map's own offset (set
with the first lamps, phase A's error), carried into C; what stays is drift in the dark.
A figure above C's own says that runs 5-6 are no longer in phase A's frame: the heading
fixes, absolute measurements against the FGM's references, turn the whole lamp map
toward the references' frame through the filter's correlations. A seed without the
calibration files (calibration off) prints its figures only.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import yaml

from fuzzyslam.config import load_config
from fuzzyslam.slam.calibration import errors_in_sigma, true_factors


def _phases(path: Path) -> dict | None:
    f = path / "metrics.json"
    return json.loads(f.read_text())["phases"] if f.is_file() else None


def _positions(tum: Path, t: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """A TUM file's times (n,) and positions (n, 2), interpolated at ``t`` if given."""
    a = np.loadtxt(tum, ndmin=2)
    if t is None:
        return a[:, 0], a[:, 1:3]
    return t, np.column_stack([np.interp(t, a[:, 0], a[:, k]) for k in (1, 2)])


def in_map_frame(est: np.ndarray, truth: np.ndarray, fit: np.ndarray) -> np.ndarray:
    """``est`` (n, 2) moved by the rigid SE(2) (Kabsch, no scale) that best takes
    ``est[fit]`` onto ``truth[fit]``.

    Parameters
    ----------
    est, truth : ndarray, shape (n, 2)
        Estimated and true positions at the same times.
    fit : ndarray of bool, shape (n,)
        The samples the transform is fitted on.

    Returns
    -------
    ndarray, shape (n, 2)
    """
    p, q = est[fit], truth[fit]
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    u, _, vt = np.linalg.svd((p - pc).T @ (q - qc))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, d]) @ u.T
    return (est - pc) @ r.T + qc


def phase_figures(seed: Path) -> str | None:
    """One seed's line of phase figures (cm), or None without its evaluations."""
    ab, c, d = (_phases(seed / f"eval_{x}") for x in ("AB", "C", "D"))
    if ab is None or c is None or d is None:
        return None
    a_cm = 100 * ab["A"]["position_m"]["mean"]
    c_cm = 100 * c["after"]["position_m"]["mean"]
    ratio = c["after"]["position_m"]["mean"] / c["A"]["position_m"]["mean"]
    t, est = _positions(seed / "C" / "trajectory.tum")
    _, truth = _positions(seed / "eval_C" / "truth.tum", t)
    moved = in_map_frame(est, truth, t <= c["A"]["t1"])
    after = t >= c["after"]["t0"]
    frame_cm = 100 * float(np.hypot(*(moved[after] - truth[after]).T).mean())
    dx, dy = (100 * d["overall"][k]["max"] for k in ("x_m", "y_m"))
    return (
        f"{seed.name} | {a_cm:.2f} | {c_cm:.2f} | {ratio:.2f} | {frame_cm:.2f} | "
        f"{dx:.2f} | {dy:.2f}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--config", default="paper.yaml")
    a = ap.parse_args()
    truth = true_factors(load_config(a.config).robot)
    seeds = sorted(a.outdir.glob("seed*"), key=lambda p: int(p.name[4:]))
    print(f"truth: left {truth[0]:.5f}, right {truth[1]:.5f}, base {truth[2]:.5f}")
    print("seed | estimate | left_scale | right_scale | base_scale | errors (sigma) | "
          "within 2 sigma")  # fmt: skip
    ok_all, any_cal = True, False
    for seed in seeds:
        for est in ("fgm", "AB", "C", "D"):
            f = seed / est / "calibration.yaml"
            if not f.is_file():
                continue
            any_cal = True
            d = yaml.safe_load(f.read_text())
            c, s = np.array(d["factors"]), np.array(d["sigma"])
            err = errors_in_sigma(c, s, truth)
            within = np.abs(err) <= 2.0
            ok_all &= bool(within.all())
            cells = " | ".join(f"{v:.5f} ± {2 * e:.5f}" for v, e in zip(c, s, strict=True))
            errs = ", ".join(f"{e:+.2f}" for e in err)
            print(f"{seed.name} | {est} | {cells} | {errs} | {'yes' if within.all() else 'no'}")
    print(f"all within 2 sigma: {'yes' if ok_all and any_cal else 'no'}")
    print()
    print("seed | A mean | C mean | C/A | C in the map's frame | D max x | D max y  (cm)")
    for seed in seeds:
        line = phase_figures(seed)
        if line is not None:
            print(line)


if __name__ == "__main__":
    main()
