"""Odometry self-calibration against the simulator's truth, per seed of a reproduce output.

    python benchmarks/calibration_vs_truth.py REPRODUCE_DIR [--config paper.yaml]

For each ``seedN`` it reads the calibration of the lamps-only run (``AB/calibration.yaml``,
the end of run 6), of the map (``fgm/calibration.yaml``, the freeze time: what phases C
and D start from) and of the C and D runs, and prints each factor with its 2-sigma bound
against the config's ``robot.left_scale``, ``right_scale``, ``base_scale`` (the
simulator's true wheels), and whether it is within 2 sigma (docs/models.md sec. 4b).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from fuzzyslam.config import load_config


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--config", default="paper.yaml")
    a = ap.parse_args()
    robot = load_config(a.config).robot
    truth = np.array([robot.left_scale, robot.right_scale, robot.base_scale])
    print(f"truth: left {truth[0]:.5f}, right {truth[1]:.5f}, base {truth[2]:.5f}")
    print("seed | estimate | left_scale | right_scale | base_scale | within 2 sigma")
    ok_all = True
    for seed in sorted(a.outdir.glob("seed*"), key=lambda p: int(p.name[4:])):
        for est in ("fgm", "AB", "C", "D"):
            f = seed / est / "calibration.yaml"
            if not f.is_file():
                continue
            d = yaml.safe_load(f.read_text())
            c, s = np.array(d["factors"]), np.array(d["sigma"])
            within = np.abs(c - truth) <= 2 * s
            ok_all &= bool(within.all())
            cells = " | ".join(f"{v:.5f} ± {2 * e:.5f}" for v, e in zip(c, s, strict=True))
            print(f"{seed.name} | {est} | {cells} | {'yes' if within.all() else 'no'}")
    print(f"all within 2 sigma: {'yes' if ok_all else 'no'}")


if __name__ == "__main__":
    main()
