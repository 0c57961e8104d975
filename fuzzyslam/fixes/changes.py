"""Change detection: new obstacles where the FLM contradicts the FGM (docs/models.md sec. 10).

The paper (sec. 4) suggests the map "could be used to detect unusual obstacles or people
walking down the corridors". Placed with the estimated pose, each FLM cell meets the
FGM cell under it; Smets' conjunctive combination of the two gives the conflict mass

    K = m_O(FLM) * m_E(FGM) + m_E(FLM) * m_O(FGM).

Its first term is "the sonar sees an obstacle where the map is confidently free": a
new obstacle (a person, a box). The FGM's free mass is first eroded (grey erosion,
the minimum over a (2k+1)^2 neighbourhood, OpenCV) so that a wall seen a cell off by
pose error does not fire. Cells with conflict above a threshold are grouped with
``cv2.connectedComponentsWithStats`` (8-connectivity, on the mask dilated by
``change_link_cells`` so that the fragments of one object join); components of at least
``change_min_cells`` conflicting cells are detections, at their conflict-weighted
centroid; size is the component's larger bounding-box side (m). The plug-in writes
``changes.csv``, ``changes.png`` (detections over the FGM) and ``/slam/changes``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from fuzzyslam.fileio import atomic_path
from fuzzyslam.fixes.base import FixAid, FlmAhead
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.summaries import ChangeSummary
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.se2 import transform_points
from fuzzyslam.slam.events import FilterView
from fuzzyslam.stamps import format_time

CHANGE_FIELDS = ("t", "x", "y", "size", "cells")


@dataclass(frozen=True)
class Change:
    """One detection: time, world position (m), size (largest bounding-box side, m), cells."""

    t: float
    x: float
    y: float
    size: float
    cells: int
    conflict: float  # summed conflict mass of the component

    def row(self) -> list[str]:
        """The row of changes.csv.

        Returns
        -------
        list of str
            t, x, y, size, cells.
        """
        return [
            format_time(self.t),
            f"{self.x:.4f}",
            f"{self.y:.4f}",
            f"{self.size:.3f}",
            str(self.cells),
        ]


def free_space(fgm: BeliefMap, erode_cells: int) -> np.ndarray:
    """FGM m(E) eroded by ``erode_cells`` (min over the neighbourhood), float32.

    Parameters
    ----------
    fgm : BeliefMap
        The frozen FGM.
    erode_cells : int
        The erosion's half-width (cells); 0: none.

    Returns
    -------
    ndarray of float32, shape (H, W)
    """
    m_e = np.ascontiguousarray(fgm.m_e, dtype=np.float32)
    if erode_cells <= 0:
        return m_e
    k = np.ones((2 * erode_cells + 1, 2 * erode_cells + 1), np.uint8)
    return cv2.erode(m_e, k, borderType=cv2.BORDER_CONSTANT, borderValue=0.0)


def conflict_image(
    flm: BeliefMap,
    pose: np.ndarray,
    fgm_grid: Any,
    free: np.ndarray,
    cells: np.ndarray | None = None,
) -> np.ndarray:
    """m_O(FLM) * m_E(FGM) on the FLM's grid, FLM placed at ``pose`` (0 off the map).

    Parameters
    ----------
    flm : BeliefMap
        The ring's FLM (robot frame), shape (h, w).
    pose : ndarray, shape (3,)
        Where the FLM is placed.
    fgm_grid : Grid
        The FGM's grid.
    free : ndarray, shape (H, W)
        :func:`free_space`.
    cells : ndarray of int, shape (n,), optional
        Flat indices of the only FLM cells computed (0 elsewhere); default all. Each
        cell's value is the same computed alone or with the others (element-wise).

    Returns
    -------
    ndarray, shape (h, w)
    """
    m_o = flm.m_o.ravel()
    if cells is None:
        cells = np.arange(m_o.size)
    world = transform_points(pose, _centre_points(flm.grid)[cells])
    iy, ix = fgm_grid.cell_of(world)
    inside = fgm_grid.inside(iy, ix)
    m_e = np.zeros(world.shape[0], dtype=np.float32)
    m_e[inside] = free[iy[inside], ix[inside]]
    k = m_o[cells] * m_e
    out = np.zeros(m_o.size, dtype=k.dtype)
    out[cells] = k
    return out.reshape(flm.grid.shape)


@lru_cache(maxsize=8)
def _centre_points(grid: Grid) -> np.ndarray:
    """The grid's cell centres as points (ny nx, 2), row-major (``Grid.centres``; read-only,
    one table per grid: :func:`conflict_image` gathers its cells' from it every ring)."""
    xs, ys = grid.centres()
    out = np.stack([xs.ravel(), ys.ravel()], axis=1)
    out.flags.writeable = False
    return out


def detect_changes(
    t: float,
    flm: BeliefMap,
    pose: np.ndarray,
    fgm_grid: Any,
    free: np.ndarray,
    min_conflict: float,
    min_cells: int,
    link: int = 1,
    free_max: np.floating | None = None,
) -> list[Change]:
    """Connected regions of strong conflict between the FLM at ``pose`` and the FGM.

    Parameters
    ----------
    t : float
        The ring's time (s).
    flm : BeliefMap
        The ring's FLM (robot frame).
    pose : ndarray, shape (3,)
        The estimated pose.
    fgm_grid : Grid
        The FGM's grid.
    free : ndarray, shape (H, W)
        :func:`free_space`.
    min_conflict : float
        A cell conflicts above it.
    min_cells : int
        Smallest component (conflicting cells).
    link : int
        Dilation (cells) joining fragments.
    free_max : numpy float, optional
        ``free.max(initial=0.0)`` when the caller has it (the detector: once per run).

    Returns
    -------
    list of Change
    """
    # K = m_O(FLM) m_E(FGM) <= m_O(FLM) max m_E (rounding is monotonic): only cells whose
    # bound exceeds the threshold can conflict above it, and only the conflicting cells'
    # K is used below
    m_o = flm.m_o.ravel()
    if free_max is None:
        free_max = free.max(initial=0.0)
    cells = np.flatnonzero(m_o * free_max.astype(m_o.dtype) > min_conflict)
    if cells.size == 0:
        return []
    k = conflict_image(flm, np.asarray(pose, float), fgm_grid, free, cells)
    mask = (k > min_conflict).astype(np.uint8)
    if not mask.any():
        return []
    # fragments of one object (two faces of a box seen by two sonars) lie a cell or two
    # apart: components are found on the mask dilated by ``link`` cells, then counted on
    # the mask's own cells
    grown = cv2.dilate(mask, np.ones((2 * link + 1, 2 * link + 1), np.uint8)) if link else mask
    n, labels, stats, _ = cv2.connectedComponentsWithStats(grown, connectivity=8)
    lab = np.where(mask.ravel() > 0, labels.ravel(), 0)
    cells = np.bincount(lab, minlength=n)
    comp = np.arange(1, n)
    comp = comp[cells[comp] >= min_cells]
    if comp.size == 0:
        return []
    # conflict-weighted centroids of the kept components (robot frame)
    xs, ys = flm.grid.centres()
    wk = np.where(lab > 0, k.ravel(), 0.0)
    wsum = np.bincount(lab, weights=wk, minlength=n)
    cx = np.bincount(lab, weights=wk * xs.ravel(), minlength=n) / np.maximum(wsum, 1e-12)
    cy = np.bincount(lab, weights=wk * ys.ravel(), minlength=n) / np.maximum(wsum, 1e-12)
    world = transform_points(pose, np.stack([cx[comp], cy[comp]], axis=1))
    extent = np.maximum(stats[comp, cv2.CC_STAT_WIDTH], stats[comp, cv2.CC_STAT_HEIGHT])
    side = np.maximum(extent - 2 * link, 1) * flm.grid.resolution
    return [
        Change(float(t), float(p[0]), float(p[1]), float(sz), int(cells[c]), float(wsum[c]))
        for p, sz, c in zip(world, side, comp, strict=True)
    ]


class ChangeDetector(FlmAhead, FixAid):
    """Plug-in of ``fuzzyslam run``: change detections per ring, written to changes.csv
    (its ``decisions`` are the detections, :class:`Change`)."""

    kind = "changes"
    draws_figures = True  # changes.png (:meth:`figures`)
    csv_name = "changes.csv"
    csv_fields = CHANGE_FIELDS

    def __init__(
        self,
        fgm: BeliefMap,
        params: FixParams,
        flm_source: Callable[[Any, np.ndarray], BeliefMap],
        start_time: float = 0.0,
    ) -> None:
        super().__init__(params, start_time)
        self.grid = fgm.grid
        self.fgm = fgm
        self.free = free_space(fgm, params.change_erode_cells)
        self.free_max = self.free.max(initial=0.0)  # detect_changes's bound, once
        self.flm_source = flm_source
        self.decisions: list[Change] = []
        self.rings = 0
        self.uncertain = 0
        self.t_first: float | None = None  # the first ring's time: changes.png's origin
        self.log = ""  # the log's name, changes.png's title (aids_for_log sets it)

    def on_ring(self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView) -> None:
        """Detect changes in the ring's FLM, when the position is known well enough.

        Parameters
        ----------
        t : float
            The ring's log time (s).
        ring : Ring
            The sonar ring (ranges (M,), max ranges (M,), fov).
        mounts : ndarray, shape (M, 3)
            The sonars' poses in base_link.
        ekf : FilterView
            The filter (its pose, covariance, dead reckoning, ``update_robot``).
        """
        if self.t_first is None:
            self.t_first = t
        if not self.started(t):
            return
        self.rings += 1
        cov = ekf.pose_cov
        if math.sqrt(max(cov[0, 0], cov[1, 1])) > self.params.change_max_sigma:
            self.uncertain += 1
            return
        flm = self.flm_source(ring, mounts)
        self.decisions += detect_changes(
            t,
            flm,
            ekf.pose,
            self.grid,
            self.free,
            self.params.change_min_conflict,
            self.params.change_min_cells,
            self.params.change_link_cells,
            self.free_max,
        )

    def summary(self) -> ChangeSummary:
        """The detector's entry in the run summary.

        Returns
        -------
        ChangeSummary
            rings, skipped_uncertain, detections, rings_with_detections.
        """
        return ChangeSummary(
            rings=self.rings,
            skipped_uncertain=self.uncertain,
            detections=len(self.decisions),
            rings_with_detections=len({c.t for c in self.decisions}),
        )

    def figures(self, outdir: Path) -> list[tuple[Callable[..., None], tuple]]:
        """changes.png (:func:`draw_changes`), as a call for the run to make (in its
        figure process, ``fuzzyslam.forked.ChildCalls``, or in itself); changes.csv is
        :meth:`write`'s.

        Parameters
        ----------
        outdir : Path
            The run's (staging) output directory.

        Returns
        -------
        list of (callable, tuple)
            ``(draw_changes, (path, fgm, detections, the run's start, the log's name))``.
        """
        t0 = self.t_first if self.t_first is not None else 0.0
        return [(draw_changes, (Path(outdir) / "changes.png", self.fgm, self.decisions, t0,
                                self.log))]  # fmt: skip

    def messages(
        self, topics: Any, start: float | None = None
    ) -> list[tuple[str, str, Any, float]]:
        """``/slam/changes`` (topics.slam_changes) for estimates.mcap: one MarkerArray per
        ring with detections, a red cylinder per detection (diameter = its size); ``start``
        is unused (the aids' common signature).

        Parameters
        ----------
        topics : Topics
            The config's topics (the aid's own and the map's).
        start : float or None
            The log's start (the map's stamp); None: no map.

        Returns
        -------
        list of (str, str, MarkerArray, float)
        """
        return change_messages(self.decisions, topics.slam_changes)


def change_messages(changes: Sequence[Change], topic: str) -> list[tuple[str, str, Any, float]]:
    """(topic, type, MarkerArray CDR bytes, t) per time with detections, in time order (map
    frame).

    Parameters
    ----------
    changes : sequence of Change
        The detections.
    topic : str
        The topic.

    Returns
    -------
    list of (str, str, bytes, float)
    """
    from itertools import groupby

    from fuzzyslam.streams import messages as M
    from fuzzyslam.streams.cdr_encode import MarkerSpec, encode_marker_array

    out = []
    for t, group in groupby(sorted(changes, key=lambda c: c.t), key=lambda c: c.t):
        markers = [
            MarkerSpec(t, "map", "changes", k, 3, (c.x, c.y, 0.0), 0.5,
                       (max(c.size, 0.1), max(c.size, 0.1), 1.0), (0.9, 0.1, 0.1, 0.7))
            for k, c in enumerate(group)
        ]  # fmt: skip
        out.append((topic, M.MARKER_ARRAY, encode_marker_array(markers), float(t)))
    return out


TIME_LABEL = "time since the run's start (s)"  # changes.png's colour bar (from t_first)


def draw_changes(
    path: Path, fgm: BeliefMap, changes: Sequence[Change], t0: float = 0.0, log: str = ""
) -> None:
    """changes.png: the frozen FGM (pignistic occupancy, grey) with every detection drawn
    over it (black-edged dots coloured by their time since the run's start, its first
    ring, viridis: dark early, light late), one column wide, sized from the map's aspect.

    Parameters
    ----------
    path : Path
        The PNG.
    fgm : BeliefMap
        The frozen FGM.
    changes : sequence of Change
        The detections.
    t0 : float
        The run's start (s, log time: its first ring): the time colour bar's origin.
    log : str
        The log's name (:func:`fuzzyslam.summary.log_name`), in the title when given.
    """
    # a Figure without pyplot (its import and figure manager are not needed for one
    # PNG), drawn once and cropped to its drawn pixels (fuzzyslam/figsave.py)
    from matplotlib.figure import Figure

    from fuzzyslam.figsave import COLUMN_W, PRINT_DPI, figure_style, fixed_layout, save_png

    g = fgm.grid
    ny, nx = g.shape
    x0, y0 = g.origin
    extent = (x0, x0 + nx * g.resolution, y0, y0 + ny * g.resolution)
    occ = fgm.m_o + 0.5 * fgm.m_t
    # inches: labels, the colour bar right, a title of one or two lines (with the log)
    left, right, bottom, top = 0.6, 0.8, 0.42, 0.45 if log else 0.3
    ax_w = COLUMN_W - left - right
    ax_h = ax_w * float(np.clip((extent[3] - extent[2]) / (extent[1] - extent[0]), 0.35, 1.4))
    with figure_style():
        fig = Figure(figsize=(COLUMN_W, bottom + ax_h + top), dpi=PRINT_DPI)
        ax = fig.add_subplot()
        fixed_layout(fig, left, right, bottom, top)
        ax.imshow(occ, origin="lower", extent=extent, cmap="gray_r", vmin=0, vmax=1)
        if changes:
            xy = np.array([[c.x, c.y] for c in changes])
            t = np.array([c.t for c in changes]) - t0
            # viridis (dark to light, every shade visible on the white corridors,
            # colour-blind safe), black-edged markers of a readable size
            sc = ax.scatter(xy[:, 0], xy[:, 1], c=t, cmap="viridis", s=20, edgecolors="black",
                            linewidths=0.6, zorder=3)  # fmt: skip
            cax = ax.inset_axes((1.0 + 0.08 / ax_w, 0.0, 0.1 / ax_w, 1.0))
            fig.colorbar(sc, cax=cax, label=TIME_LABEL)
        of = f"\n{log}" if log else ""  # the log on a line of its own (one column wide)
        ax.set_title(f"change detections ({len(changes)}) over the frozen FGM{of}", y=1.0)
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal")
        with atomic_path(path) as tmp:
            save_png(fig, tmp, PRINT_DPI, tight=True)
