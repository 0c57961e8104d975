"""Figures of the map stage (matplotlib, Agg): the paper's Fig. 1 (FGM with path and
lamps), the conflict map, and Fig. 2 (corridor segments and an FLM beside their Hough
planes with the peaks marked)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from fuzzyslam.figsave import fixed_layout, save_png
from fuzzyslam.fileio import atomic_path
from fuzzyslam.maps.flm import build_flm
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.hough import WallDirection, flm_wall_direction, wall_weights
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.references import Reference
from fuzzyslam.rundir import read_landmarks
from fuzzyslam.streams.logmeta import World

DPI = 110  # figures are made at their PNG's dpi: the layout's text sizes are the drawing's


def _save(fig, path: Path, tight: bool = False) -> None:
    with atomic_path(path) as tmp:
        save_png(fig, tmp, DPI, tight)  # one draw, RGB at a cheaper zlib level
    plt.close(fig)


def fig_fgm(
    path: Path,
    fgm: BeliefMap,
    poses: np.ndarray,
    refs: list[Reference],
    world: World | None,
    landmarks: np.ndarray | None,
) -> None:
    """The paper's Fig. 1: BetP(O) of the FGM, the path, references, lamps.

    Parameters
    ----------
    path : Path
        The PNG.
    fgm : BeliefMap
        The FGM.
    poses : ndarray, shape (N, 3)
        The path.
    refs : list of Reference
        The corridor references.
    world : World or None
        The true walls and lamps (simulated logs).
    landmarks : ndarray, shape (K, 2), or None
        Estimated lamps.
    """
    fig, ax = plt.subplots(figsize=(9, 6), dpi=DPI)
    im = ax.imshow(
        fgm.pignistic_occupied(),
        origin="lower",
        extent=fgm.grid.extent,
        cmap="gray_r",
        vmin=0,
        vmax=1,
    )
    fig.colorbar(im, ax=ax, shrink=0.7, label="BetP(occupied) (probability)")
    ax.plot(poses[:, 0], poses[:, 1], "-", color="tab:blue", lw=0.8, label="path")
    for k, r in enumerate(refs):
        poly = np.vstack([r.region, r.region[:1]])
        ax.plot(poly[:, 0], poly[:, 1], "--", color="tab:orange", lw=0.8,
                label="corridor region: id, reference angle" if k == 0 else "_")  # fmt: skip
        c = r.region.mean(axis=0)
        ax.annotate(f"{r.id}: {np.rad2deg(r.angle):.2f} deg", c, color="tab:orange", fontsize=8)
    if world is not None and len(world.lamps):
        la = world.lamp_array
        ax.plot(la[:, 0], la[:, 1], "o", mfc="none", color="gold", label="true lamps")
    if landmarks is not None and len(landmarks):
        ax.plot(landmarks[:, 0], landmarks[:, 1], "x", color="tab:red", label="estimated lamps")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    ax.set_title("Fuzzy global map: BetP(occupied) (dark = occupied)", y=1.0)
    ax.legend(loc="upper right", fontsize=8)
    _save(fig, path)


def fig_conflict(path: Path, fgm: BeliefMap) -> None:
    """Conflict mass m(emptyset) per cell.

    Parameters
    ----------
    path : Path
        The PNG.
    fgm : BeliefMap
        The FGM.
    """
    fig, ax = plt.subplots(figsize=(9, 6), dpi=DPI)
    im = ax.imshow(fgm.m_c, origin="lower", extent=fgm.grid.extent, cmap="magma", vmin=0)
    fig.colorbar(im, ax=ax, label="m(conflict) (mass)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    ax.set_title("FGM contradiction (conflict mass)", y=1.0)
    _save(fig, path)


def _hough_panel(ax, wd: WallDirection, title: str) -> None:
    if wd.plane is None:
        ax.set_title(title + " (no evidence)", y=1.0)
        return
    pl = wd.plane
    im = ax.imshow(
        pl.acc,
        origin="lower",
        aspect="auto",
        cmap="viridis",
        extent=(0, 180, pl.rhos[0], pl.rhos[-1]),
    )
    ax.figure.colorbar(im, ax=ax, label="votes (m of wall)")
    seen = set()
    for k, pk in enumerate(wd.peaks):
        # the peaks of the wall direction (red), and the strongest peak of another
        # direction (white, last) when the map has one (an ambiguous wall)
        second = k == len(wd.peaks) - 1 and bool(wd.second_strength)
        label = "peak of another direction" if second else "wall peaks (the direction)"
        ax.plot(
            np.rad2deg(pk.theta),
            pk.rho,
            "o",
            color="white" if second else "red",
            mfc="none",
            ms=8,
            label=label if label not in seen else "_",
        )
        seen.add(label)
    if wd.peaks:
        ax.legend(fontsize=6, loc="upper right", framealpha=0.7)
    ax.set_xlabel("theta (deg)")
    ax.set_ylabel("rho (m)")
    ax.set_title(title, fontsize=9, y=1.0)


def crop_cells(
    values: np.ndarray, grid: Grid, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The cells of ``values`` (the grid's (ny, nx) array) that cover the box [lo, hi]
    (x, y in m) with one cell to spare, and their extent for ``imshow(origin="lower")``:
    a panel that shows one corridor draws its cells, not the whole building's (Freiburg
    079's hough.png: ten panels, each resampling the whole map).

    Parameters
    ----------
    values : ndarray, shape (ny, nx)
        Per-cell values on ``grid``.
    grid : Grid
        The grid.
    lo, hi : ndarray, shape (2,)
        The box's lower-left and upper-right corners (m).

    Returns
    -------
    part : ndarray, shape (h, w)
        The cells (a view).
    extent : (float, float, float, float)
        (xmin, xmax, ymin, ymax) of those cells (m).
    """
    res, (ox, oy) = grid.resolution, grid.origin
    ny, nx = values.shape
    ix0 = min(max(int(np.floor((lo[0] - ox) / res)) - 1, 0), nx)
    ix1 = min(max(int(np.ceil((hi[0] - ox) / res)) + 1, ix0), nx)
    iy0 = min(max(int(np.floor((lo[1] - oy) / res)) - 1, 0), ny)
    iy1 = min(max(int(np.ceil((hi[1] - oy) / res)) + 1, iy0), ny)
    extent = (ox + ix0 * res, ox + ix1 * res, oy + iy0 * res, oy + iy1 * res)
    return values[iy0:iy1, ix0:ix1], extent


HOUGH_COLUMNS = 6  # corridor panels per row of hough.png


def fig_hough(
    path: Path,
    fgm: BeliefMap,
    refs: list[Reference],
    flm: BeliefMap | None,
    flm_wd: WallDirection | None,
    params: MapParams,
) -> None:
    """The paper's Fig. 2: each corridor segment's wall evidence and an FLM (top) with
    their Hough planes and peaks (bottom); a grid of such pairs, ``HOUGH_COLUMNS`` per
    row, for buildings with many corridors.

    Parameters
    ----------
    path : Path
        The PNG.
    fgm : BeliefMap
        The FGM.
    refs : list of Reference
        The corridor references.
    flm : BeliefMap or None
        One ring's FLM.
    flm_wd : WallDirection or None
        Its Hough wall direction.
    params : MapParams
        The ``fgm:`` section.
    """
    n = len(refs) + (1 if flm is not None else 0)
    cols = min(max(n, 1), HOUGH_COLUMNS)
    blocks = -(-max(n, 1) // cols)
    fig, grid = plt.subplots(
        2 * blocks, cols, figsize=(3.6 * cols, 7 * blocks), squeeze=False, dpi=DPI
    )
    for ax in grid.ravel():
        ax.set_axis_off()

    def pair(k: int):
        top, bottom = grid[2 * (k // cols), k % cols], grid[2 * (k // cols) + 1, k % cols]
        top.set_axis_on()
        bottom.set_axis_on()
        return top, bottom

    w = wall_weights(fgm, params.wall_threshold)
    for k, r in enumerate(refs):
        lo, hi = r.region.min(axis=0), r.region.max(axis=0)
        ax, bottom = pair(k)
        part, extent = crop_cells(w, fgm.grid, lo, hi)
        im = ax.imshow(part, origin="lower", extent=extent, cmap="gray_r", vmin=0, vmax=1)
        fig.colorbar(im, ax=ax, shrink=0.8, label="wall weight (0-1)")
        poly = np.vstack([r.region, r.region[:1]])
        ax.plot(poly[:, 0], poly[:, 1], "--", color="tab:orange", lw=0.8, label="region")
        ax.legend(fontsize=6, loc="upper right", framealpha=0.7)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
        ax.set_title(f"{r.name}: {np.rad2deg(r.angle):.2f} deg", fontsize=9, y=1.0)
        if r.wall is not None:
            _hough_panel(bottom, r.wall, f"Hough, strength {r.strength:.2f} m")
    if flm is not None and flm_wd is not None:
        ax, bottom = pair(n - 1)
        im = ax.imshow(
            wall_weights(flm, params.wall_threshold),
            origin="lower",
            extent=flm.grid.extent,
            cmap="gray_r",
            vmin=0,
            vmax=1,
        )
        fig.colorbar(im, ax=ax, shrink=0.8, label="wall weight (0-1)")
        ax.plot(0, 0, "^", color="tab:blue", label="robot")
        ax.legend(fontsize=6, loc="upper right", framealpha=0.7)
        ax.set_xlabel("x, robot frame (m)")
        ax.set_ylabel("y, robot frame (m)")
        ax.set_aspect("equal")
        ax.set_title(f"FLM (robot frame): {np.rad2deg(flm_wd.angle):.2f} deg", fontsize=9, y=1.0)
        _hough_panel(bottom, flm_wd, f"FLM Hough, strength {flm_wd.strength:.2f} m")
    # fixed margins and gaps (inches) for the tick labels, axis labels, titles and colour
    # bars' labels between the panels, the blank rest cropped (fuzzyslam/figsave.py)
    fixed_layout(fig, 0.75, 0.6, 0.6, 0.35, hspace=0.8, wspace=1.1)
    _save(fig, path, tight=True)


def pick_flm_ring(poses: np.ndarray, refs: list[Reference]) -> int:
    """A ring in the middle of the longest corridor (for the Fig. 2 FLM).

    Parameters
    ----------
    poses : ndarray, shape (N, 3)
        The rings' poses.
    refs : list of Reference
        The corridor references.

    Returns
    -------
    int
        The ring's index.
    """
    if not refs:
        return len(poses) // 2
    best = max(refs, key=lambda r: r.stretch.length if r.stretch is not None else 0.0)
    c = best.region.mean(axis=0)
    return int(np.argmin(np.hypot(poses[:, 0] - c[0], poses[:, 1] - c[1])))


def write_all(
    outdir: Path,
    fgm: BeliefMap,
    poses: np.ndarray,
    refs: list[Reference],
    world: World | None,
    landmarks_path: Path | None,
    times: np.ndarray,
    ranges: np.ndarray,
    rmax: np.ndarray,
    fov: float,
    mounts: np.ndarray,
    params: MapParams,
) -> list[str]:
    """Write fgm.png, conflict.png, hough.png into ``outdir``; returns their names.

    Parameters
    ----------
    outdir : Path
        The (staging) map directory.
    fgm : BeliefMap
        The frozen FGM.
    poses : ndarray, shape (N, 3)
        The rings' poses.
    refs : list of Reference
        The corridor references.
    world : World or None
        The true world (simulated logs).
    landmarks_path : Path or None
        A run's landmarks.yaml.
    times : ndarray, shape (N,)
        The rings' times (s).
    ranges : ndarray, shape (N, M)
        Their readings.
    rmax : ndarray, shape (N, M)
        Their maximum ranges.
    fov : float
        The cone's full angle (rad).
    mounts : ndarray, shape (M, 3)
        The sensors' poses on the robot.
    params : MapParams
        The ``fgm:`` section.

    Returns
    -------
    list of str
    """
    lm = read_landmarks(landmarks_path)[0] if landmarks_path is not None else None
    fig_fgm(outdir / "fgm.png", fgm, poses, refs, world, lm)
    fig_conflict(outdir / "conflict.png", fgm)
    k = pick_flm_ring(poses, refs)
    flm = build_flm(ranges[k], rmax[k], fov, mounts, params)
    fig_hough(outdir / "hough.png", fgm, refs, flm, flm_wall_direction(flm, params), params)
    return ["fgm.png", "conflict.png", "hough.png"]
