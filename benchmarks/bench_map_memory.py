"""Benchmark of a large building's map: peak memory of the corridor references and of
fgm.png, side by side with the whole-grid way of doing each.

Usage::

    python benchmarks/bench_map_memory.py [--width 400] [--height 300] [--resolution 0.1]

A ring of corridors (3 m wide, walls painted as m(O) = 0.8 one cell thick) and a cross
corridor on a map of WIDTH x HEIGHT metres, with the path along their centre lines, as
a large building's FGM would be (Killian Court's is about 250 x 200 m). Prints one JSON
object: the map's cells, then for each step its peak of traced memory (MB, tracemalloc,
above what was allocated before it) and its time:

- ``references``: :func:`fuzzyslam.maps.references.extract_references` (each corridor's
  Hough on its region's bounding box);
- ``references_whole_grid``: the same Houghs on whole-grid arrays (the cell centres and
  wall weights of the whole map, masked per corridor: the code before 2026-12-04), and
  whether the two give the same references (they must);
- ``fgm_png``: :func:`fuzzyslam.maps.figures.fig_fgm` (the map max-pooled to the figure's
  pixels);
- ``fgm_png_unpooled``: the same figure's image drawn from the whole map (matplotlib
  resamples it itself).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
import tracemalloc
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np

from fuzzyslam.maps import figures
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.hough import dominant_direction, wall_weights
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.references import (
    extract_references,
    merge_stretches,
    straight_stretches,
)


def corridor_map(width: float, height: float, res: float) -> tuple[BeliefMap, np.ndarray]:
    """A ring of corridors 5 m in from the map's edges and a cross corridor, walls 1.5 m
    either side of each centre line; the path along the centre lines (10 cm steps)."""
    grid = Grid.covering(0.0, 0.0, width, height, res)
    bm = BeliefMap.vacuous(grid)
    x0, y0, x1, y1 = 5.0, 5.0, width - 5.0, height - 5.0
    xm = 0.5 * (x0 + x1)
    legs = [((x0, y0), (x1, y0)), ((x1, y0), (x1, y1)), ((x1, y1), (x0, y1)),
            ((x0, y1), (x0, y0)), ((xm, y0), (xm, y1))]  # fmt: skip
    ny, nx = grid.shape
    for (ax, ay), (bx, by) in legs:
        for off in (-1.5, 1.5):  # a wall each side, one cell thick
            if ay == by:
                c0, c1 = sorted((int(ax / res), int(bx / res)))
                bm.m_o[min(int((ay + off) / res), ny - 1), c0:c1] = 0.8
            else:
                r0, r1 = sorted((int(ay / res), int(by / res)))
                bm.m_o[r0:r1, min(int((ax + off) / res), nx - 1)] = 0.8
    bm.m_t[:] = np.where(bm.m_o > 0, 0.2, 1.0)
    path = []
    for (ax, ay), (bx, by) in legs[:4]:
        n = int(np.hypot(bx - ax, by - ay) / 0.1)
        path.append(np.column_stack([np.linspace(ax, bx, n), np.linspace(ay, by, n)]))
    return bm, np.vstack(path)


def whole_grid_references(fgm: BeliefMap, path_xy: np.ndarray, params: MapParams) -> list:
    """The references' Houghs on whole-grid arrays (the way before the bounding boxes):
    each corridor's (angle, strength, cells)."""
    stretches = merge_stretches(straight_stretches(path_xy, params), params)
    X, Y = fgm.grid.centres()
    w_all = wall_weights(fgm, params.wall_threshold)
    trim = params.segment_end_trim
    out = []
    for st in stretches:
        s0, s1 = st.s0 + trim, st.s1 - trim
        if s1 - s0 < params.segment_min_length / 2:
            continue
        d = st.direction
        s = (X - st.point[0]) * d[0] + (Y - st.point[1]) * d[1]
        q = (X - st.point[0]) * -d[1] + (Y - st.point[1]) * d[0]
        mask = (s >= s0) & (s <= s1) & (np.abs(q) <= params.segment_band)
        wd = dominant_direction(X, Y, np.where(mask, w_all, 0.0), params, fgm.grid.resolution)
        out.append((wd.angle, wd.strength, wd.cells))
    return out


def unpooled_fgm_png(path: Path, fgm: BeliefMap) -> None:
    """fgm.png's image drawn from the whole map, at the same size and dpi."""
    fig, ax, _ = figures._map_axes(fgm.grid.extent, figures.WIDE_W, figures.LEGEND_RIGHT)
    ax.imshow(fgm.pignistic_occupied(), origin="lower", extent=fgm.grid.extent,
              cmap="gray_r", vmin=0, vmax=1)  # fmt: skip
    fig.savefig(path, dpi=figures.DPI)
    plt.close(fig)


def measured(fn, *args):
    """fn(*args)'s answer, its peak traced memory above the start (MB) and time (s)."""
    tracemalloc.start()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    out = fn(*args)
    dt = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    return out, round(peak / 1e6, 1), round(dt, 2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--width", type=float, default=400.0)
    ap.add_argument("--height", type=float, default=300.0)
    ap.add_argument("--resolution", type=float, default=0.1)
    a = ap.parse_args()
    params = MapParams(resolution=a.resolution)
    bm, path = corridor_map(a.width, a.height, a.resolution)
    out: dict = {"map_m": [a.width, a.height], "cells": int(bm.m_o.size)}
    refs, peak, dt = measured(extract_references, bm, path, params)
    out["references"] = {"peak_mb": peak, "time_s": dt, "corridors": len(refs)}
    whole, peak, dt = measured(whole_grid_references, bm, path, params)
    same = [(r.angle, r.strength, r.cells) for r in refs] == whole
    out["references_whole_grid"] = {"peak_mb": peak, "time_s": dt, "same_references": same}
    with tempfile.TemporaryDirectory() as tmp:
        _, peak, dt = measured(figures.fig_fgm, Path(tmp) / "fgm.png", bm, np.column_stack(
            [path, np.zeros(len(path))]), refs, None, None)  # fmt: skip
        out["fgm_png"] = {"peak_mb": peak, "time_s": dt}
        _, peak, dt = measured(unpooled_fgm_png, Path(tmp) / "whole.png", bm)
        out["fgm_png_unpooled"] = {"peak_mb": peak, "time_s": dt}
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
