"""Figures of the map stage (matplotlib, Agg): the paper's Fig. 1 (FGM with path and
lamps), the conflict map, and Fig. 2 (corridor segments and an FLM beside their Hough
planes with the peaks marked)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib import patheffects
from matplotlib.lines import Line2D
from matplotlib.ticker import MaxNLocator, MultipleLocator

from fuzzyslam.figsave import (
    BLACK,
    BLUE,
    COLUMN_W,
    ORANGE,
    PRINT_DPI,
    VERMILLION,
    WIDE_W,
    fixed_layout,
    save_png,
    styled,
)
from fuzzyslam.fileio import atomic_path
from fuzzyslam.maps.flm import build_flm
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.maps.hough import WallDirection, flm_wall_direction, wall_weights
from fuzzyslam.maps.params import MapParams
from fuzzyslam.maps.references import Reference
from fuzzyslam.rundir import read_landmarks
from fuzzyslam.streams.logmeta import World
from fuzzyslam.summary import log_name

DPI = PRINT_DPI  # made at print size and at the PNG's dpi (fuzzyslam/figsave.py's style)
LEGEND_RIGHT = 2.5  # fgm.png: its colour bar, legend and corridor key right of the axes (in)
M_LEFT, M_BOTTOM, M_TOP = 0.6, 0.42, 0.3  # a map's margins (inches, 8-9 pt text)
CBAR_RIGHT = 0.75  # a colour bar right of a map: gap, bar, tick labels, label (inches)
HALO = [patheffects.withStroke(linewidth=2.5, foreground="white")]  # labels over the map


def _save(fig, path: Path, tight: bool = False) -> None:
    with atomic_path(path) as tmp:
        save_png(fig, tmp, DPI, tight)  # one draw, RGB at a cheaper zlib level
    plt.close(fig)


def _map_axes(extent, width: float, right: float, top: float = M_TOP):
    """A figure ``width`` inches wide holding one map at equal scale: its axes' height from
    the map's aspect (between 0.35 and 1.4 of its width), the margins fixed.

    Returns the figure, the axes and the axes' size (inches)."""
    ax_w = width - M_LEFT - right
    aspect = float(np.clip((extent[3] - extent[2]) / max(extent[1] - extent[0], 1e-9), 0.35, 1.4))
    ax_h = ax_w * aspect
    fig, ax = plt.subplots(figsize=(width, M_BOTTOM + ax_h + top), dpi=DPI)
    fixed_layout(fig, M_LEFT, right, M_BOTTOM, top)
    return fig, ax, (ax_w, ax_h)


def _side_colorbar(fig, ax, im, ax_w: float, label: str):
    """A colour bar as tall as the axes, 0.08 inches right of them and 0.1 inches wide."""
    cax = ax.inset_axes((1.0 + 0.08 / ax_w, 0.0, 0.1 / ax_w, 1.0))
    return fig.colorbar(im, cax=cax, label=label)


@styled
def fig_fgm(
    path: Path,
    fgm: BeliefMap,
    poses: np.ndarray,
    refs: list[Reference],
    world: World | None,
    landmarks: np.ndarray | None,
    log: str = "",
) -> None:
    """The paper's Fig. 1: BetP(O) of the FGM, the path, references, landmarks.

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
        Estimated landmarks (lamps of a simulated world).
    log : str
        The log's path, named in the title.
    """
    noun = "lamps" if world is not None else "landmarks"
    fig, ax, (ax_w, _ax_h) = _map_axes(fgm.grid.extent, WIDE_W, LEGEND_RIGHT)
    betp, extent = _pooled(fgm.pignistic_occupied(), fgm.grid, ax_w)
    im = ax.imshow(betp, origin="lower", extent=extent, cmap="gray_r", vmin=0, vmax=1)
    _side_colorbar(fig, ax, im, ax_w, "BetP(occupied)")
    ax.plot(poses[:, 0], poses[:, 1], "-", color=BLUE, lw=1.0, label="path")
    centre = np.mean(np.reshape(fgm.grid.extent, (2, 2)), axis=1)
    key = []
    for k, r in enumerate(refs):
        poly = np.vstack([r.region, r.region[:1]])
        ax.plot(poly[:, 0], poly[:, 1], "--", color=ORANGE, lw=1.0,
                label="corridor (number: key)" if k == 0 else "_")  # fmt: skip
        # its number at the region's corner farthest from the map's centre (off the
        # path, which runs down the region's middle), haloed white: the key beside says
        # its reference angle
        corner = r.region[int(np.argmax(np.hypot(*(r.region - centre).T)))]
        ax.annotate(str(r.id), corner, fontsize=8, fontweight="bold", color=BLACK,
                    ha="center", va="center", path_effects=HALO)  # fmt: skip
        key.append(f"{r.id}: {np.rad2deg(r.angle):.2f} deg")
    # the estimates small, the true lamps as larger rings over them: both show where
    # they coincide
    if landmarks is not None and len(landmarks):
        ax.plot(landmarks[:, 0], landmarks[:, 1], "X", mfc=VERMILLION, mec=BLACK, mew=0.5,
                ms=4.5, zorder=3, label=f"estimated {noun}")  # fmt: skip
    if world is not None and len(world.lamps):
        la = world.lamp_array
        ax.plot(la[:, 0], la[:, 1], "o", color=BLACK, mfc="none", mew=1.0, ms=9, zorder=4,
                label="true lamps")  # fmt: skip
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    name = log_name(log)
    ax.set_title(f"Fuzzy global map{f' of {name}' if name else ''}: BetP(occupied)", y=1.0)
    # the legend and the corridors' key right of the colour bar (none over the map)
    x_leg = 1.0 + CBAR_RIGHT / ax_w
    leg = ax.legend(loc="upper left", bbox_to_anchor=(x_leg, 1.0), frameon=False,
                    borderaxespad=0.0)  # fmt: skip
    if key:
        # no measuring: the key hangs below the legend's rows at a fixed offset (points)
        rows = len(ax.get_legend_handles_labels()[0]) + 1
        shown = key if len(key) <= 12 else [*key[:11], f"... ({len(key) - 11} more)"]
        ax.annotate("corridor: reference angle\n" + "\n".join(shown), (x_leg, 1.0),
                    xycoords="axes fraction", xytext=(0, -rows * 12), textcoords="offset points",
                    fontsize=8, va="top", ha="left", annotation_clip=False)  # fmt: skip
    assert leg is not None
    _save(fig, path, tight=True)


@styled
def fig_conflict(path: Path, fgm: BeliefMap, log: str = "") -> None:
    """Conflict mass m(∅) per cell, the figure sized from the map's aspect and the colour
    bar as tall as the map.

    Parameters
    ----------
    path : Path
        The PNG.
    fgm : BeliefMap
        The FGM.
    log : str
        The log's path, named in the title.
    """
    fig, ax, (ax_w, _ax_h) = _map_axes(fgm.grid.extent, COLUMN_W, CBAR_RIGHT)
    conflict, extent = _pooled(fgm.m_c, fgm.grid, ax_w)
    im = ax.imshow(conflict, origin="lower", extent=extent, cmap="magma", vmin=0)
    _side_colorbar(fig, ax, im, ax_w, "conflict mass m(∅)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_aspect("equal")
    name = log_name(log)
    ax.set_title(f"FGM conflict{f': {name}' if name else ''}", y=1.0)
    _save(fig, path, tight=True)


def _wrapped_plane(wd: WallDirection) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The Hough plane over normal angles [-HOUGH_PAD_DEG, 180 + HOUGH_PAD_DEG) (deg),
    scaled to its largest vote: a line (theta, rho) is (theta + 180, -rho), so the
    columns beyond 0 and 180 are the other end's, rho mirrored (to the nearest row), and a
    peak at 0 or 180 deg shows whole. Returns the image and its ``imshow`` extent."""
    pl = wd.plane
    assert pl is not None
    acc = pl.acc / max(float(pl.acc.max()), 1e-12)
    th = np.rad2deg(pl.thetas)
    dth = float(th[1] - th[0]) if th.size > 1 else 1.0
    k = min(int(np.ceil(HOUGH_PAD_DEG / dth)), th.size)
    rhos = pl.rhos
    dr = float(rhos[1] - rhos[0]) if rhos.size > 1 else 1.0
    j = np.rint((-rhos - rhos[0]) / dr).astype(int)  # the row of -rho
    ok = (j >= 0) & (j < rhos.size)
    mirrored = np.zeros_like(acc)
    mirrored[ok] = acc[j[ok]]
    wide = np.hstack([mirrored[:, th.size - k :], acc, mirrored[:, :k]])
    extent = (th[0] - (k + 0.5) * dth, th[-1] + (k + 0.5) * dth,
              rhos[0] - 0.5 * dr, rhos[-1] + 0.5 * dr)  # fmt: skip
    return wide, extent


def strongest_title(strength: float, prefix: str = "") -> str:
    """A Hough panel's title: its strongest line's votes, metres of wall at full belief
    (the wall direction's ``strength``).

    Parameters
    ----------
    strength : float
        The strongest line's strength (m).
    prefix : str
        Put before it ("FLM: ").

    Returns
    -------
    str
    """
    return f"{prefix}strongest line: {strength:.2f} m of wall"


def _hough_panel(ax, wd: WallDirection | None, title: str, cbar_of: dict) -> None:
    """A Hough plane (votes over the line normal's angle and rho) with its peaks: the wall
    direction's (red) and the strongest of another direction (white, when there is one),
    each also drawn at its other end (theta +- 180 deg, -rho) where the padding shows it."""
    ax.set_xlabel("θ: angle of line normal (deg)")
    ax.set_ylabel("ρ (m)")
    ax.xaxis.set_major_locator(MultipleLocator(45))
    ax.yaxis.set_major_locator(MaxNLocator(4))
    # the title at the labels' size: as wide as the panel with its tick labels, over none
    # of the neighbour's
    if wd is None or wd.plane is None:
        ax.set_title("no wall evidence (no Hough plane)", y=1.0, fontsize=HOUGH_TITLE_PT)
        ax.set_xlim(-HOUGH_PAD_DEG, 180 + HOUGH_PAD_DEG)
        return
    wide, extent = _wrapped_plane(wd)
    im = ax.imshow(wide, origin="lower", aspect="auto", cmap="viridis", vmin=0.0, vmax=1.0,
                   extent=extent, interpolation="nearest")  # fmt: skip
    _shared_colorbar(im, cbar_of, "votes")
    for t in (0.0, 180.0):  # the plane's period: beyond these lines it repeats
        ax.axvline(t, color="white", lw=0.6, ls=":")
    for k, pk in enumerate(wd.peaks):
        # the peaks of the wall direction (red), and the strongest peak of another
        # direction (white, last) when the map has one (an ambiguous wall)
        second = k == len(wd.peaks) - 1 and bool(wd.second_strength)
        th, rho = np.rad2deg(pk.theta), pk.rho
        at = [(th, rho)]  # and the other end where the padding holds the whole circle
        if th < HOUGH_PAD_DEG - PEAK_ROOM_DEG:
            at.append((th + 180.0, -rho))
        if th > 180.0 - HOUGH_PAD_DEG + PEAK_ROOM_DEG:
            at.append((th - 180.0, -rho))
        xs, ys = zip(*at, strict=True)
        ax.plot(xs, ys, **(PEAK_OTHER if second else PEAK_WALL))
    ax.set_xlim(-HOUGH_PAD_DEG, 180 + HOUGH_PAD_DEG)
    ax.set_ylim(extent[2], extent[3])
    ax.set_title(title, y=1.0, fontsize=HOUGH_TITLE_PT)


def _shared_colorbar(im, cbar_of: dict, kind: str) -> None:
    """Give ``im`` the figure's one colour bar of its ``kind`` (the images of a kind share
    its colour map and its 0-1 range): the first image of the kind is drawn into it."""
    cbar_of.setdefault(kind, []).append(im)


def _box_of_aspect(lo: np.ndarray, hi: np.ndarray, aspect: float) -> tuple[np.ndarray, np.ndarray]:
    """The box [lo, hi] grown about its centre by 4 % and to height / width = ``aspect``
    (a panel's shape: a map drawn at equal scale fills its panel)."""
    c, size = (lo + hi) / 2.0, np.maximum(hi - lo, 1e-6) * 1.04  # the box's edges inside
    if size[1] / size[0] < aspect:
        size = np.array([size[0], size[0] * aspect])
    else:
        size = np.array([size[1] / aspect, size[1]])
    return c - size / 2.0, c + size / 2.0


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


HOUGH_COLUMNS = 3  # corridor panels per row of hough.png (a 7-inch column holds three)
HOUGH_PAD_DEG = 15.0  # the Hough planes drawn over [-15, 195) deg: peaks at 0 or 180 whole
PEAK_ROOM_DEG = 7.0  # a peak's circle is about this wide on the theta axis: none cut
# hough.png's layout (inches): every panel the same size, the margins and gaps hold the
# tick labels, axis labels and titles; the legend on top, the two colour bars right
PANEL_W, PANEL_H = 1.55, 1.3
H_LEFT, H_RIGHT, H_BOTTOM, H_TOP = 0.55, 0.85, 0.45, 0.85
H_WSPACE, H_HSPACE = 0.55, 0.6
HOUGH_TITLE_PT = 8.0  # a Hough plane's title ("strongest line: 4.99 m of wall")
HOUGH_REFS = 3  # hough.png: the strongest corridors (by Hough peak) drawn, and the FLM
POOL_PX = 2.0  # a wall cell drawn at least this many pixels wide (max-pooled when smaller)
# the peaks: red (the wall direction) and white (another), black-edged to show on any
# colour of the plane and in the legend
_EDGE = [patheffects.withStroke(linewidth=2.6, foreground="black")]
PEAK_WALL = {
    "ls": "none",
    "marker": "o",
    "mfc": "none",
    "color": "#FF3030",
    "ms": 7,
    "mew": 1.3,
    "path_effects": _EDGE,
    "label": "wall peaks (the wall direction)",
}
PEAK_OTHER = {"ls": "none", "marker": "o", "mfc": "none", "color": "white", "ms": 7,
              "mew": 1.3, "path_effects": _EDGE,
              "label": "strongest peak of another direction"}  # fmt: skip
REGION = {"ls": "--", "color": ORANGE, "lw": 1.0, "label": "corridor region"}
ROBOT = {"ls": "none", "marker": "^", "color": BLUE, "ms": 6, "label": "robot (FLM)"}


def max_pool(
    values: np.ndarray, extent: tuple[float, float, float, float], factor: int
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """``values`` reduced by taking the largest of each ``factor`` by ``factor`` block of
    cells (the last blocks padded with zeros), and the extent of the blocks: a wall one
    cell wide stays whole when the picture has fewer pixels than the map cells.

    Parameters
    ----------
    values : ndarray, shape (h, w)
        Per-cell values (non-negative).
    extent : (float, float, float, float)
        (xmin, xmax, ymin, ymax) of the cells (``imshow(origin="lower")``).
    factor : int
        Cells per block side (1: unchanged).

    Returns
    -------
    pooled : ndarray, shape (ceil(h / factor), ceil(w / factor))
    extent : (float, float, float, float)
        The blocks' extent (grown by the padding).
    """
    if factor <= 1 or values.size == 0:
        return values, extent
    h, w = values.shape
    hb, wb = -(-h // factor), -(-w // factor)
    padded = np.zeros((hb * factor, wb * factor), dtype=values.dtype)
    padded[:h, :w] = values
    pooled = padded.reshape(hb, factor, wb, factor).max(axis=(1, 3))
    dx, dy = (extent[1] - extent[0]) / w, (extent[3] - extent[2]) / h
    return pooled, (
        extent[0],
        extent[0] + wb * factor * dx,
        extent[2],
        extent[2] + hb * factor * dy,
    )


def pool_factor(cells: int, inches: float, dpi: float) -> int:
    """The block size of :func:`max_pool` that draws a cell at least ``POOL_PX`` pixels
    wide: ``cells`` cells across a panel ``inches`` wide at ``dpi``.

    Parameters
    ----------
    cells : int
        Cells across the panel.
    inches : float
        The panel's width.
    dpi : float
        Dots per inch.

    Returns
    -------
    int
        At least 1.
    """
    return max(1, int(np.ceil(POOL_PX * cells / max(inches * dpi, 1.0))))


def _pooled(values: np.ndarray, grid: Grid, inches: float) -> tuple[np.ndarray, tuple]:
    """A whole map's ``values`` max-pooled (:func:`max_pool`) to draw on axes ``inches``
    wide at ``DPI``, and their extent: matplotlib's resampling of a large map otherwise
    holds several float64 copies of it (a 400 x 300 m map at 10 cm: 0.7 GB)."""
    factor = pool_factor(max(values.shape), inches, DPI)
    values, extent = max_pool(values, grid.extent, factor)
    return values, extent


def strongest(refs: list[Reference], n: int = HOUGH_REFS) -> list[Reference]:
    """The ``n`` references of the strongest Hough peak (``strength``), in their order.

    Parameters
    ----------
    refs : list of Reference
        The corridor references.
    n : int
        How many.

    Returns
    -------
    list of Reference
    """
    keep = sorted(range(len(refs)), key=lambda k: -float(refs[k].strength))[:n]
    return [refs[k] for k in sorted(keep)]


@styled
def fig_hough(
    path: Path,
    fgm: BeliefMap,
    refs: list[Reference],
    flm: BeliefMap | None,
    flm_wd: WallDirection | None,
    params: MapParams,
    log: str = "",
) -> None:
    """The paper's Fig. 2: the wall evidence of the ``HOUGH_REFS`` corridors of the
    strongest Hough peaks and an FLM (top) with their Hough planes and peaks (bottom); a
    grid of such pairs, ``HOUGH_COLUMNS`` per row, every panel ``PANEL_W`` by ``PANEL_H``
    inches, a title and one legend on top and one colour bar per kind of image (wall
    weight, votes) on the right. Wall weights are max-pooled (:func:`max_pool`) where a
    panel has fewer pixels than cells.

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
    log : str
        The log's path, named in the title.
    """
    total = len(refs)
    refs = strongest(refs)
    n = len(refs) + (1 if flm is not None else 0)
    cols = min(max(n, 1), HOUGH_COLUMNS)
    blocks = -(-max(n, 1) // cols)
    rows = 2 * blocks
    w = H_LEFT + H_RIGHT + cols * PANEL_W + (cols - 1) * H_WSPACE
    h = H_TOP + H_BOTTOM + rows * PANEL_H + (rows - 1) * H_HSPACE
    fig, grid = plt.subplots(rows, cols, figsize=(w, h), squeeze=False, dpi=DPI)
    for ax in grid.ravel():
        ax.set_axis_off()
    aspect = PANEL_H / PANEL_W
    cbar_of: dict = {}
    drawn = {"region": False, "robot": False, "other": False}

    def pair(k: int):
        top, bottom = grid[2 * (k // cols), k % cols], grid[2 * (k // cols) + 1, k % cols]
        top.set_axis_on()
        bottom.set_axis_on()
        for ax in (top, bottom):
            ax.xaxis.set_major_locator(MaxNLocator(4))
            ax.yaxis.set_major_locator(MaxNLocator(4))
        return top, bottom

    def other(wd: WallDirection | None) -> bool:
        return (
            wd is not None and wd.plane is not None and bool(wd.peaks) and bool(wd.second_strength)
        )

    wts = wall_weights(fgm, params.wall_threshold)
    for k, r in enumerate(refs):
        lo, hi = _box_of_aspect(r.region.min(axis=0), r.region.max(axis=0), aspect)
        ax, bottom = pair(k)
        # the cells of the corridor's region only (0.5 m around it), the panel around them
        rlo, rhi = r.region.min(axis=0) - 0.5, r.region.max(axis=0) + 0.5
        part, extent = crop_cells(wts, fgm.grid, np.maximum(lo, rlo), np.minimum(hi, rhi))
        part, extent = max_pool(part, extent, pool_factor(max(part.shape), PANEL_W, DPI))
        im = ax.imshow(part, origin="lower", extent=extent, cmap="gray_r", vmin=0, vmax=1,
                       interpolation="nearest")  # fmt: skip
        _shared_colorbar(im, cbar_of, "wall")
        poly = np.vstack([r.region, r.region[:1]])
        ax.plot(poly[:, 0], poly[:, 1], **REGION)
        drawn["region"] = True
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
        ax.set_title(f"{r.name}: {np.rad2deg(r.angle):.2f} deg", y=1.0)
        _hough_panel(bottom, r.wall, strongest_title(r.strength), cbar_of)
        drawn["other"] |= other(r.wall)
    if flm is not None and flm_wd is not None:
        ax, bottom = pair(n - 1)
        e = flm.grid.extent
        lo, hi = _box_of_aspect(np.array([e[0], e[2]]), np.array([e[1], e[3]]), aspect)
        fw = wall_weights(flm, params.wall_threshold)
        fw, fe = max_pool(fw, e, pool_factor(max(fw.shape), PANEL_W, DPI))
        im = ax.imshow(fw, origin="lower", extent=fe, cmap="gray_r", vmin=0, vmax=1,
                       interpolation="nearest")  # fmt: skip
        _shared_colorbar(im, cbar_of, "wall")
        ax.plot(0, 0, **ROBOT)
        drawn["robot"] = True
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_xlabel("x, robot frame (m)")
        ax.set_ylabel("y, robot frame (m)")
        ax.set_aspect("equal")
        ax.set_title(f"FLM (robot frame): {np.rad2deg(flm_wd.angle):.2f} deg", y=1.0)
        _hough_panel(bottom, flm_wd, strongest_title(flm_wd.strength, "FLM: "), cbar_of)
        drawn["other"] |= other(flm_wd)
    # fixed margins and gaps (inches) for the tick labels, axis labels and titles between
    # the panels, the blank rest cropped (fuzzyslam/figsave.py)
    fixed_layout(fig, H_LEFT, H_RIGHT, H_BOTTOM, H_TOP, hspace=H_HSPACE, wspace=H_WSPACE)
    # one colour bar per kind, right of the first block's last panel (its top row: wall
    # weight, its bottom row: votes); the images of a kind share it (same map, 0-1)
    labels = {"wall": (0, "wall weight (0-1)"), "votes": (1, "votes / panel's peak (0-1)")}
    for kind, ims in cbar_of.items():
        row, label = labels[kind]
        box = grid[row, cols - 1].get_position()
        cax = fig.add_axes((box.x1 + 0.12 / w, box.y0, 0.1 / w, box.height), label="<colorbar>")
        cb = fig.colorbar(ims[0], cax=cax, label=label)
        cb.ax.yaxis.set_major_locator(MaxNLocator(3))
        for im in ims[1:]:
            im.colorbar = cb  # drawn with the colour bar's map and range
    entries = ((REGION, drawn["region"]), (ROBOT, drawn["robot"]), (PEAK_WALL, True),
               (PEAK_OTHER, drawn["other"]))  # fmt: skip
    handles = [Line2D([], [], **kw) for kw, on in entries if on]
    name = log_name(log)
    shown = f"the {len(refs)} strongest of {total} corridors" if total > len(refs) else "corridors"
    fig.text(H_LEFT / w, 1.0 - 0.03 / h, f"Fig. 2{f': {name}' if name else ''}: {shown}"
             f"{' and an FLM' if flm is not None else ''}", va="top", ha="left",
             fontsize=9)  # fmt: skip
    fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(H_LEFT / w, 1.0 - 0.22 / h),
               ncol=2, frameon=False, handlelength=2.2, columnspacing=1.5,
               borderaxespad=0.0)  # fmt: skip
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
    log: str = "",
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
    mounts : ndarray, shape (M, 3) or (N, M, 3)
        The sensors' poses on the robot (each ring's, deskewed, for sonars fired in
        sequence).
    params : MapParams
        The ``fgm:`` section.
    log : str
        The log's path, named in the titles.

    Returns
    -------
    list of str
    """
    lm = read_landmarks(landmarks_path)[0] if landmarks_path is not None else None
    fig_fgm(outdir / "fgm.png", fgm, poses, refs, world, lm, log=log)
    fig_conflict(outdir / "conflict.png", fgm, log=log)
    k = pick_flm_ring(poses, refs)
    flm = build_flm(ranges[k], rmax[k], fov, mounts if mounts.ndim == 2 else mounts[k], params)
    fig_hough(outdir / "hough.png", fgm, refs, flm, flm_wall_direction(flm, params), params,
              log=log)  # fmt: skip
    return ["fgm.png", "conflict.png", "hough.png"]
