"""The paper's figures (1, 3, 4) and a consistency plot, drawn with matplotlib (Agg) into PNGs.

Each ``fig_*`` function takes arrays/dataclasses and a path and writes one PNG.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.lines import Line2D
from numpy.typing import NDArray

from fuzzyslam.evaluation.align import Similarity
from fuzzyslam.evaluation.core import Estimate, Evaluation, Truth
from fuzzyslam.evaluation.lamps import LampMatch
from fuzzyslam.figsave import (
    BLACK,
    BLUE,
    COLUMN_W,
    ESTIMATE_KINDS,
    EVENT_COLOURS,
    EXPECTED,
    GREEN,
    ORANGE,
    PRINT_DPI,
    PURPLE,
    SERIES,  # fmt: skip
    SERIES_DASHES,
    SKY,
    VERMILLION,
    WIDE_W,
    fixed_layout,
    save_png,
    series_styles,
    styled,
)
from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.slam.health import chi2_quantile
from fuzzyslam.streams.logmeta import World
from fuzzyslam.summary import log_name

Array = NDArray[np.float64]
DPI = PRINT_DPI  # made at print size and at the PNG's dpi (fuzzyslam/figsave.py's style)
# the Okabe-Ito palette (figsave.py); the odometry as in every figure (ESTIMATE_KINDS)
C_TRUTH, C_EST, C_ODOM = BLACK, BLUE, ESTIMATE_KINDS["odometry"][1]["color"]


# Margins of the figures' fixed layouts (inches, 8-9 pt text; fuzzyslam/figsave.py): tick
# labels and an axis label left, a title on top, tick labels and an axis label below (and
# the legend of the events under them); the blank rest is cropped. Titles are placed at
# y=1.0 (as matplotlib places them by default, above axes without top tick labels):
# otherwise it measures every y tick label at each draw to place them
LEFT, RIGHT, TOP, BOTTOM = 0.6, 0.12, 0.3, 0.45
TOP2 = 0.45  # a title of two lines
XLABEL_ROOM = 0.42  # below the axes: tick labels and the x label
LEGEND_ROW = 0.155  # one legend row at 8 pt (inches)
LEGEND_SIDE = 2.45  # consistency's and compare's legends right of their axes
TIME_LABEL = "time since the log's start (s)"


def log_start(truth: Truth) -> float:
    """The log's start: the time origin of every time axis (the truth's first stamp, or
    the first run's start when earlier).

    Parameters
    ----------
    truth : Truth
        The truth.

    Returns
    -------
    float
        Log time (s).
    """
    t0 = float(truth.t[0]) if truth.t.size else 0.0
    if truth.scenario is not None:
        starts = [a for _r, a, _b in truth.scenario.run_intervals()]
        if starts:
            t0 = min(t0, min(starts))
    return t0


def landmark_noun(truth: Truth) -> str:
    """What the landmarks are called in the figures: "lamps" for a simulated world's
    ceiling lamps, "landmarks" otherwise (a real log's detections, ``--landmarks-truth``).

    Parameters
    ----------
    truth : Truth
        The truth.

    Returns
    -------
    str
    """
    return "lamps" if truth.world is not None else "landmarks"


def run_title(truth: Truth, est: Estimate) -> str:
    """The log and the run a figure is of: ``LOG: LABEL`` (file names, :func:`log_name`).

    Parameters
    ----------
    truth : Truth
        The truth (its source: the log or truth file).
    est : Estimate
        The estimate (its label).

    Returns
    -------
    str
    """
    log = log_name(truth.source)
    return f"{log}: {est.label}" if log else est.label


def _legend_rows(n: int, ncol: int) -> int:
    return -(-n // max(ncol, 1))


def events_legend(fig: plt.Figure, ax: plt.Axes, handles: list, bottom: float) -> None:
    """The events' legend under ``ax`` (the last axes), below its x label: its top
    ``XLABEL_ROOM`` inches under the axes, in two columns.

    Parameters
    ----------
    fig : Figure
        The figure (laid out: :func:`fuzzyslam.figsave.fixed_layout`).
    ax : Axes
        The bottom axes.
    handles : list
        The handles of :func:`mark_events` (nothing drawn without one).
    bottom : float
        The figure's bottom margin (inches, :func:`events_bottom`).
    """
    if not handles:
        return
    h = fig.get_size_inches()[1]
    x = ax.get_position().x0 + ax.get_position().width / 2.0
    fig.legend(handles=handles, loc="upper center", bbox_to_anchor=(x, (bottom - XLABEL_ROOM) / h),
               ncol=min(len(handles), 2), frameon=False, borderaxespad=0.0)  # fmt: skip


def events_bottom(handles: int) -> float:
    """The bottom margin (inches) that holds the x label and the events' legend (two
    columns).

    Parameters
    ----------
    handles : int
        The legend's entries.

    Returns
    -------
    float
        Inches.
    """
    return XLABEL_ROOM + _legend_rows(handles, 2) * LEGEND_ROW + 0.12 if handles else BOTTOM


def _save(fig: plt.Figure, path: Path) -> None:
    # one draw with the fixed layout, cropped to the drawn pixels (fuzzyslam/figsave.py)
    save_png(fig, path, DPI, tight=True)
    plt.close(fig)


def _moved(est: Estimate, to_truth: Similarity | None) -> Estimate:
    """The estimate in the truth's frame: poses, dead reckoning and landmarks moved by the
    evaluation's alignment (``Evaluation.to_truth``; unchanged without one)."""
    if to_truth is None:
        return est
    from dataclasses import replace

    return replace(
        est,
        poses=to_truth.apply_poses(est.poses),
        landmarks=to_truth.apply(est.landmarks) if est.landmarks is not None else None,
        odometry=(est.odometry[0], to_truth.apply_poses(est.odometry[1]))
        if est.odometry is not None
        else None,
    )


@styled
def fig1_paths(
    path: Path,
    truth: Truth,
    est: Estimate,
    fgm: BeliefMap | None = None,
    lamp_match: LampMatch | None = None,
    title: str = "",
    to_truth: Similarity | None = None,
) -> None:
    """Fig. 1: true, estimated and odometry-only paths; true and estimated landmarks
    (duplicated and missed ones marked when lamp_match is given); walls; the FGM
    underneath when given. Everything in the truth's frame: the estimate, its dead
    reckoning, landmarks and map moved by ``to_truth`` (the evaluation's alignment, the
    one its numbers use), when given.

    Parameters
    ----------
    path : Path
        The PNG.
    truth : Truth
        The truth (path, world, true landmarks).
    est : Estimate
        The estimate as the run wrote it.
    fgm : BeliefMap, optional
        The map, in the estimate's frame.
    lamp_match : LampMatch, optional
        The evaluation's landmark matching (indices of ``est.landmarks``).
    title : str
        The title (default: the log, the run and what is drawn).
    to_truth : Similarity, optional
        The rigid motion from the estimate's frame to the truth's.
    """
    noun = landmark_noun(truth)
    raw_lm = est.landmarks
    est = _moved(est, to_truth)
    world: World | None = truth.world
    true_lm = truth.landmark_array
    pts = [truth.poses[:, :2], est.poses[:, :2]]
    if world is not None:
        pts.append(world.wall_array.reshape(-1, 2))
    if est.odometry is not None:
        pts.append(est.odometry[1][:, :2])
    if est.landmarks is not None and est.landmarks.size:
        pts.append(est.landmarks[:, :2])
    if true_lm is not None and true_lm.size:
        pts.append(np.asarray(true_lm, dtype=float)[:, :2])
    if fgm is not None and to_truth is None:
        e = fgm.grid.extent
        pts.append(np.array([[e[0], e[2]], [e[1], e[3]]]))
    allp = np.vstack([p for p in pts if p.size])
    allp = allp[np.isfinite(allp).all(axis=1)]
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    pad = 0.04 * float(np.max(hi - lo)) + 0.1
    lo, hi = lo - pad, hi + pad
    # the axes' shape from the data's (equal scale), between 0.6 and 1.3 of its width
    right = RIGHT + (0.75 if fgm is not None else 0.0)
    ax_w = COLUMN_W - LEFT - right
    ratio = float(np.clip((hi[1] - lo[1]) / (hi[0] - lo[0]), 0.6, 1.3))
    ax_h = ax_w * ratio
    centre, size = (lo + hi) / 2.0, hi - lo
    if size[1] / size[0] < ratio:
        size[1] = size[0] * ratio
    else:
        size[0] = size[1] / ratio
    lo, hi = centre - size / 2.0, centre + size / 2.0

    fig = plt.figure(figsize=(COLUMN_W, 1.0), dpi=DPI)  # its height set below
    ax = fig.add_subplot()
    if fgm is not None:
        im = ax.imshow(fgm.pignistic_occupied(), origin="lower", extent=fgm.grid.extent,
                       cmap="Greys", vmin=0.0, vmax=1.0, interpolation="nearest")  # fmt: skip
        if to_truth is not None:  # the map moved with the estimate
            from matplotlib.transforms import Affine2D

            m = np.eye(3)
            m[:2, :2], m[:2, 2] = to_truth.scale * to_truth.rotation, to_truth.translation
            im.set_transform(Affine2D(m) + ax.transData)
        cax = ax.inset_axes((1.04, 0.0, 0.05, 1.0))
        fig.colorbar(im, cax=cax, label="FGM BetP(occupied)")
    if world is not None:
        for i, w in enumerate(world.wall_array):
            ax.plot(w[[0, 2]], w[[1, 3]], color="0.45" if fgm is None else "tab:olive",
                    lw=1.2, label=("true walls" if i == 0 else None))  # fmt: skip
    if est.odometry is not None:
        op = est.odometry[1]
        ax.plot(op[:, 0], op[:, 1], color=C_ODOM, lw=1.0, ls="--", label="odometry only")
    ax.plot(est.poses[:, 0], est.poses[:, 1], color=C_EST, lw=1.3, label="estimate")
    # the truth over the estimate, dashed: where they agree both show
    ax.plot(truth.poses[:, 0], truth.poses[:, 1], color=C_TRUTH, lw=1.0, ls=(0, (4, 2)),
            label="true path", zorder=4)  # fmt: skip
    if true_lm is not None and len(true_lm):
        la = np.asarray(true_lm, dtype=float)
        ax.scatter(la[:, 0], la[:, 1], s=36, marker="o", facecolors="none", edgecolors=ORANGE,
                   linewidths=1.2, label=f"true {noun}", zorder=5)  # fmt: skip
        if world is not None:  # the simulated lamps' numbers (fig4's axis)
            for i, (x, y) in enumerate(la[:, :2]):
                ax.annotate(str(i), (x, y), xytext=(3, 3), textcoords="offset points",
                            fontsize=7)  # fmt: skip
    if est.landmarks is not None and est.landmarks.size:
        ax.scatter(est.landmarks[:, 0], est.landmarks[:, 1], s=24, marker="x", color=GREEN,
                   linewidths=1.2, label=f"estimated {noun}", zorder=6)  # fmt: skip
        left = (  # the estimates the matching left over: (indices, size, colour, width, label)
            (lamp_match.spurious, 24, PURPLE, 1.2,
             f"spurious ({{}}, > {lamp_match.max_dist:.2f} m)"),
            (lamp_match.duplicates, 50, VERMILLION, 1.6, "duplicated ({})"),
        ) if lamp_match is not None else ()  # fmt: skip
        for idx, size, colour, width, label in left:
            if idx:
                d = est.landmarks[idx]
                ax.scatter(d[:, 0], d[:, 1], s=size, marker="x", color=colour,
                           linewidths=width, label=label.format(len(d)), zorder=7)  # fmt: skip
        if lamp_match is not None and lamp_match.missed and true_lm is not None:
            m = np.asarray(true_lm, dtype=float)[lamp_match.missed]
            ax.scatter(m[:, 0], m[:, 1], s=60, marker="s", facecolors="none",
                       edgecolors=VERMILLION, linewidths=1.2, label=f"missed ({len(m)})",
                       zorder=7)  # fmt: skip
    del raw_lm
    ax.scatter(*truth.poses[0, :2], s=40, marker="*", color="k", zorder=7, label="start")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_ylabel("y (m)")
    frame = "truth frame, estimate aligned" if to_truth is not None else "map frame"
    ax.set_xlabel(f"x (m), {frame}")
    what = f"{'FGM, ' if fgm is not None else ''}paths and {noun}"
    ax.set_title(title or f"Fig. 1: {what}\n{run_title(truth, est)}", y=1.0)
    ax.grid(alpha=0.3)
    # the legend under the axes, two columns (none over the map)
    n = len(ax.get_legend_handles_labels()[0])
    bottom = XLABEL_ROOM + _legend_rows(n, 2) * LEGEND_ROW + 0.08
    h = TOP2 + ax_h + bottom
    fig.set_size_inches(COLUMN_W, h)
    fixed_layout(fig, LEFT, right, bottom, TOP2)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -XLABEL_ROOM / ax_h), ncol=2,
              frameon=False, borderaxespad=0.0, columnspacing=1.0, handlelength=1.8)  # fmt: skip
    _save(fig, path)


def mark_events(axes: list[plt.Axes], truth: Truth, t0: float = 0.0) -> list:
    """Vertical lines at run starts (labelled), the FGM freeze, lamp failures and bumps,
    at their times since ``t0``.

    Parameters
    ----------
    axes : list of Axes
        The axes, sharing their time axis (the run labels on the first).
    truth : Truth
        The truth (or anything with its ``scenario`` and ``freeze_run``).
    t0 : float
        The time origin (s, log time: :func:`log_start`).

    Returns
    -------
    list
        The legend handles of the event kinds drawn (for :func:`events_legend`).
    """
    if truth.scenario is None:
        return []
    style = {
        "run start": {"color": "0.6", "lw": 1.0, "ls": ":"},
        "FGM frozen": {"color": EVENT_COLOURS["FGM frozen"], "lw": 1.2, "ls": "-"},
        "lamp failure": {"color": EVENT_COLOURS["lamp failure"], "lw": 1.2, "ls": "--"},
        "bump": {"color": EVENT_COLOURS["bump"], "lw": 1.0, "ls": "-."},
    }
    times = event_times(truth)
    for r, a, _t1 in truth.scenario.run_intervals():
        axes[0].annotate(f"run {r}", (a - t0, 1.0), xycoords=("data", "axes fraction"),
                         xytext=(2, -9), textcoords="offset points", fontsize=8)  # fmt: skip
    handles = []
    for kind, ts in times.items():
        for t in ts:
            for ax in axes:
                ax.axvline(t - t0, **style[kind])
        if ts:
            # the runs are numbered at their starts: "run starts", the others counted
            label = "run starts" if kind == "run start" else f"{kind} ({len(ts)})"
            handles.append(Line2D([], [], label=label, **style[kind]))
    return handles


def event_times(truth: Truth) -> dict[str, list[float]]:
    """The times (s, log time) of a simulated log's events: run starts, the FGM freeze,
    lamp failures, bumps (empty lists without a scenario).

    Parameters
    ----------
    truth : Truth
        The truth (its scenario and freeze run).

    Returns
    -------
    dict
        ``{"run start": [...], "FGM frozen": [...], "lamp failure": [...], "bump": [...]}``.
    """
    times: dict[str, list[float]] = {k: [] for k in ("run start", "FGM frozen",
                                                      "lamp failure", "bump")}  # fmt: skip
    if truth.scenario is None:
        return times
    times["run start"] = [a for _r, a, _b in truth.scenario.run_intervals()]
    for e in truth.scenario.events:
        if e.kind == "lamp_failure":
            times["lamp failure"].append(e.t)
        elif e.kind == "bump":
            times["bump"].append(e.t)
    if truth.freeze_run is not None:
        t_freeze = truth.scenario.run_end_time(truth.freeze_run)
        if t_freeze is not None:
            times["FGM frozen"].append(t_freeze)
    return times


@styled
def fig3_errors(path: Path, truth: Truth, ev: Evaluation, title: str = "") -> None:
    """Fig. 3: x, y (cm) and heading (deg) errors against the time since the log's start,
    +-2 sigma from the covariance, run boundaries, the FGM freeze, lamp failures and bumps
    marked.

    Parameters
    ----------
    path : Path
        The PNG.
    truth : Truth
        The truth (its start and events).
    ev : Evaluation
        The evaluation.
    title : str
        The title.
    """
    t0 = log_start(truth)
    t = ev.assoc.t - t0
    fig, axes = plt.subplots(3, 1, figsize=(COLUMN_W, 4.6), sharex=True, dpi=DPI)
    scale = [100.0, 100.0, 180.0 / np.pi]
    names = ["x error (cm)", "y error (cm)", "heading err. (deg)"]
    for k, ax in enumerate(axes):
        e = ev.errors[:, k] * scale[k]
        if ev.sigma is not None:
            s2 = 2.0 * ev.sigma[:, k] * scale[k]
            ax.fill_between(t, -s2, s2, color=C_EST, alpha=0.18, lw=0, label="±2σ (filter)")
        ax.plot(t, e, color=C_EST, lw=1.0, label="estimate − truth")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_ylabel(names[k])
        ax.grid(alpha=0.3)
        # every error inside the axes (the largest, not a percentile: no clipped data);
        # the +-2 sigma band may leave them where it is wider than the errors
        lim = float(np.nanmax(np.abs(e))) if np.isfinite(e).any() else 1.0
        if ev.sigma is not None:
            lim = max(lim, float(np.nanpercentile(2.0 * ev.sigma[:, k] * scale[k], 99.5)))
        lim = lim * 1.1 if np.isfinite(lim) and lim > 0 else 1.0
        ax.set_ylim(-lim, lim)
    # the curves' legend with the events' under the axes (over none of the data, the
    # band or the run labels)
    handles = axes[0].get_legend_handles_labels()[0] + mark_events(list(axes), truth, t0)
    axes[-1].set_xlabel(TIME_LABEL)
    axes[0].set_title(title or f"Fig. 3: pose errors\n{run_title(truth, ev_label(ev))}", y=1.0)
    bottom = events_bottom(len(handles))
    fixed_layout(fig, LEFT, RIGHT, bottom, TOP2, hspace=0.12)
    events_legend(fig, axes[-1], handles, bottom)
    _save(fig, path)


def ev_label(ev: Evaluation) -> Estimate:
    """A stand-in estimate holding the evaluation's label (for :func:`run_title`).

    Parameters
    ----------
    ev : Evaluation
        The evaluation.

    Returns
    -------
    Estimate
    """
    return Estimate(np.zeros(0), np.zeros((0, 3)), label=str(ev.typed.label))


@styled
def fig4_lamp_errors(
    path: Path,
    per_lamp: Mapping[str, Array],
    title: str = "",
    max_dist: float | None = None,
    noun: str = "lamp",
    run: str = "",
) -> None:
    """Fig. 4: position error of each true landmark (cm), one bar group per landmark, one
    bar per labelled estimate (e.g. end of run 4, end of run 6, with bumps). Missed
    landmarks: a cross.

    Parameters
    ----------
    path : Path
        The PNG.
    per_lamp : mapping
        Label -> errors of the true landmarks (m; NaN: missed).
    title : str
        The title.
    max_dist : float, optional
        The matching distance (m), for the axis label.
    noun : str
        What the landmarks are ("lamp" or "landmark").
    run : str
        The log and run (:func:`run_title`), the title's second line.
    """
    labels = list(per_lamp)
    bottom = XLABEL_ROOM + 0.05 + len(labels) * LEGEND_ROW + 0.05
    top = TOP2 if run and not title else TOP
    fig, ax = plt.subplots(figsize=(COLUMN_W, 1.7 + top + bottom), dpi=DPI)
    n = max((len(v) for v in per_lamp.values()), default=0)
    width = 0.8 / max(len(labels), 1)
    x = np.arange(n)
    for j, lab in enumerate(labels):
        colour = SERIES[j % len(SERIES)]
        v = np.asarray(per_lamp[lab], dtype=float) * 100.0
        pos = x[: v.size] - 0.4 + width * (j + 0.5)
        mean = np.nanmean(v) if np.isfinite(v).any() else np.nan
        bars = ax.bar(pos, np.nan_to_num(v), width=width * 0.95, color=colour,
                      label=f"{lab} (mean {significant(mean)} cm)")  # fmt: skip
        miss = ~np.isfinite(v)
        if miss.any():
            ax.scatter(pos[miss], np.zeros(miss.sum()), marker="x", s=24, zorder=5,
                       color=bars.patches[0].get_facecolor())  # fmt: skip
    ax.set_xticks(x)
    ax.set_xticklabels([str(i) for i in x])
    ax.set_xlabel(
        f"true {noun} index (x: none within {max_dist * 100:.0f} cm)"
        if max_dist
        else f"true {noun} index"
    )
    ax.set_ylabel(f"{noun} error (cm)")
    second = "\n" + run if run else ""
    ax.set_title(title or f"Fig. 4: per-{noun} position error{second}", y=1.0)
    ax.grid(axis="y", alpha=0.3)
    fixed_layout(fig, LEFT, RIGHT, bottom, top)
    ax_w = COLUMN_W - LEFT - RIGHT
    ax.legend(loc="upper left", bbox_to_anchor=(-(LEFT - 0.05) / ax_w, -XLABEL_ROOM / 1.7),
              frameon=False, borderaxespad=0.0)  # fmt: skip
    _save(fig, path)


def significant(v: float, digits: int = 2) -> str:
    """``v`` with ``digits`` significant figures, no exponent (0.14, 0.063, 12, 130).

    Parameters
    ----------
    v : float
        The value.
    digits : int
        Significant figures.

    Returns
    -------
    str
    """
    if not np.isfinite(v) or v == 0:
        return f"{v:.{digits - 1}f}" if np.isfinite(v) else "nan"
    raw = digits - 1 - int(np.floor(np.log10(abs(v))))  # decimals; < 0: rounds to tens
    return f"{round(float(v), raw):.{max(0, raw)}f}"


def log_floor(*values: Array) -> float:
    """The lower limit of a log axis from the data: half the 1st percentile of every
    positive finite value (the few below it are drawn at it; no empty decades under the
    data), 1e-3 without one.

    Parameters
    ----------
    *values : ndarray
        The values drawn.

    Returns
    -------
    float
    """
    pos = [
        v[np.isfinite(v) & (v > 0)] for v in (np.asarray(x, dtype=float).ravel() for x in values)
    ]
    pos = [p for p in pos if p.size]
    if not pos:
        return 1e-3
    return float(np.percentile(np.concatenate(pos), 1.0)) / 2.0


def running_mean(v: Array, frac: float = 0.02) -> Array:
    """Centred moving average over w = max(5, frac * n) samples (NaNs ignored), one value
    per sample: sample i averages the finite values of ``v[i - w + 1 + (w - 1) // 2 : i +
    (w - 1) // 2 + 1]`` (numpy's ``convolve(mode="same")`` window) that exist, so that a
    series shorter than the window (n < w, even n = 0 or 1) keeps its length.

    Parameters
    ----------
    v : array_like, shape (n,)
        The series.
    frac : float
        The window as a fraction of the samples (at least 5 samples).

    Returns
    -------
    ndarray, shape (n,)
        The averages; NaN where the window holds no finite value.
    """
    v = np.asarray(v, dtype=float).ravel()
    n = v.size
    w = max(5, int(frac * n))
    ok = np.isfinite(v)
    # prefix sums of the finite values and of their count: a window's sum is a difference
    num = np.concatenate([[0.0], np.cumsum(np.where(ok, v, 0.0))])
    den = np.concatenate([[0], np.cumsum(ok)])
    i = np.arange(n)
    lo = np.clip(i - (w - 1 - (w - 1) // 2), 0, n)
    hi = np.clip(i + (w - 1) // 2 + 1, 0, n)
    cnt = den[hi] - den[lo]
    return np.where(cnt > 0, (num[hi] - num[lo]) / np.maximum(cnt, 1), np.nan)


GAP_FACTOR = 5.0  # a gap in a series: over this many times its median sample spacing


def break_gaps(t: Array, v: Array, factor: float = GAP_FACTOR) -> tuple[Array, Array]:
    """A series with a NaN in each of its gaps (a spacing over ``factor`` times the median
    positive spacing), so that its line breaks there instead of joining the two sides.

    Parameters
    ----------
    t : array_like, shape (n,)
        The times, in order.
    v : array_like, shape (n,)
        The values.
    factor : float
        The gap, in median spacings.

    Returns
    -------
    (ndarray, ndarray)
        The times and values with a point (mid-gap, NaN) in each gap.
    """
    t, v = np.asarray(t, dtype=float).ravel(), np.asarray(v, dtype=float).ravel()
    dt = np.diff(t)
    pos = dt[dt > 0]
    if pos.size < 2:
        return t, v
    gaps = np.flatnonzero(dt > factor * float(np.median(pos)))
    mid = (t[gaps] + t[gaps + 1]) / 2.0
    return np.insert(t, gaps + 1, mid), np.insert(v, gaps + 1, np.nan)


# mark_below's triangles and their legend entry
BELOW_MARK = {"marker": "v", "mec": BLACK, "mew": 0.3, "ls": "none"}
BELOW_MS = 3.5


def mark_below(ax: plt.Axes, t: Array, v: Array, floor: float, colour: str) -> bool:
    """Triangles on the bottom edge of ``ax`` at the times of the values under ``floor``
    (the log axis's lower limit, where they are drawn); True when there is one.

    Parameters
    ----------
    ax : Axes
        A log-scale axes with ``floor`` its lower limit.
    t : array_like
        The times (x, data).
    v : array_like
        The values.
    floor : float
        The lower limit.
    colour : str
        The triangles' colour (the series').

    Returns
    -------
    bool
    """
    low = np.asarray(v, dtype=float) < floor
    if not low.any():
        return False
    # x in data, y in axes coordinates: on the edge whatever the limits
    ax.plot(np.asarray(t, dtype=float)[low], np.zeros(int(low.sum())), ms=BELOW_MS,
            color=colour, clip_on=False, zorder=5, transform=ax.get_xaxis_transform(),
            **BELOW_MARK)  # fmt: skip
    return True


def below_handle(markerscale: float = 1.0) -> Line2D:
    """The legend entry of :func:`mark_below`'s triangles (for a legend of
    ``markerscale``: drawn at their size)."""
    return Line2D([], [], ms=BELOW_MS / markerscale, color="0.5",
                  label="below the axis (on its edge)", **BELOW_MARK)  # fmt: skip


@styled
def fig_consistency(path: Path, truth: Truth, est: Estimate, ev: Evaluation) -> bool:
    """NEES (3 dof) against time with its per-sample 95 % band, and NIS of accepted updates
    per kind, normalised by dof. Returns False (nothing drawn) without covariance or updates."""
    has_nis = est.updates is not None and est.updates.t.size > 0
    if ev.nees is None and not has_nis:
        return False
    t0 = log_start(truth)
    fig, axes = plt.subplots(2, 1, figsize=(WIDE_W, 3.8), sharex=True, dpi=DPI)
    ax = axes[0]
    side = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": 8, "frameon": False}
    if ev.nees is not None:
        lo, hi = chi2_quantile(0.025, 3), chi2_quantile(0.975, 3)
        # every sample inside the axes: those under the floor (zeros) drawn at it, and
        # marked on the axis's edge
        floor = min(log_floor(ev.nees), 10.0 ** np.floor(np.log10(lo)))
        tn = ev.assoc.t - t0
        ax.semilogy(*break_gaps(tn, np.maximum(ev.nees, floor)), color=SKY, lw=0.6,
                    label=f"NEES (mean {np.nanmean(ev.nees):.2f})")  # fmt: skip
        # the running mean broken where the samples stop (no line across a gap)
        ax.semilogy(*break_gaps(tn, running_mean(ev.nees)), color=BLUE, lw=1.4,
                    label="running mean (2 %)")  # fmt: skip
        ax.axhspan(lo, hi, color=ORANGE, alpha=0.15, lw=0, label="95 % band, one sample (3 dof)")
        ax.axhline(3.0, color=EXPECTED, lw=0.9, ls="--", label="expected NEES = 3")
        ax.set_ylim(bottom=floor)
        extra = [below_handle()] if mark_below(ax, tn, ev.nees, floor, SKY) else []
        ax.legend(handles=ax.get_legend_handles_labels()[0] + extra, **side)
    ax.set_ylabel("NEES (pose, 3 dof)")
    ax.grid(alpha=0.3, which="both")
    ax = axes[1]
    if has_nis:
        u = est.updates
        assert u is not None
        kinds = []
        for kind in sorted(set(u.kind.tolist())):
            m = (u.kind == kind) & u.accepted & (u.dof > 0) & np.isfinite(u.nis)
            if m.any():
                kinds.append((kind, m, u.nis[m] / u.dof[m]))
        floor = min(log_floor(*(v for _k, _m, v in kinds)), 0.1)
        below = False
        for j, (kind, m, v) in enumerate(kinds):
            colour = SERIES[j % len(SERIES)]
            tk = u.t[m] - t0
            ax.semilogy(tk, np.maximum(v, floor), ".", ms=2, alpha=0.5, color=colour,
                        label=f"{kind} ({m.sum()} accepted, mean {v.mean():.2f})")  # fmt: skip
            # broken where the kind's updates stop (a lamp-less stretch): no line across
            ax.semilogy(*break_gaps(tk, running_mean(v)), color=colour, lw=1.4,
                        ls=SERIES_DASHES[j % len(SERIES_DASHES)],
                        label=f"{kind}, running mean")  # fmt: skip
            below |= mark_below(ax, tk, v, floor, colour)
        ax.axhline(1.0, color=EXPECTED, lw=0.9, ls="--", label="expected NIS / dof = 1")
        ax.set_ylim(bottom=floor)
        extra = [below_handle(4.0)] if below else []
        ax.legend(handles=ax.get_legend_handles_labels()[0] + extra, **side, markerscale=4)
    ax.set_ylabel("NIS / dof (dimensionless)")
    ax.set_xlabel(TIME_LABEL)
    ax.grid(alpha=0.3, which="both")
    handles = mark_events(list(axes), truth, t0)
    axes[0].set_title(f"Filter consistency (NEES, NIS): {run_title(truth, est)}", y=1.0)
    bottom = events_bottom(len(handles))
    fixed_layout(fig, LEFT, RIGHT + LEGEND_SIDE, bottom, TOP, hspace=0.15)
    events_legend(fig, axes[-1], handles, bottom)
    _save(fig, path)
    return True


def fig4_sets(truth: Truth, est: Estimate, ev: Evaluation) -> dict[str, Array]:
    """Per-lamp errors to draw in Fig. 4: the map at the end of the FGM-freeze run and of the
    last run (the paper's 'run 4' and 'run 6') when snapshots exist, else the final map."""
    by_run = ev.lamp_match_by_run
    if by_run:
        last = max(by_run)
        runs = sorted({r for r in (truth.freeze_run, last) if r is not None and r in by_run})
        return {f"end of run {r}": by_run[r].per_true for r in runs}
    if ev.lamp_match is not None:
        return {"final map": ev.lamp_match.per_true}
    return {}


@styled
def fig_compare(path: Path, truth: Truth, runs: Sequence[tuple[str, Evaluation]]) -> None:
    """Position error (cm, log scale) against the time since the log's start of several
    estimates of one truth, with the run boundaries, the FGM freeze, lamp failures and
    bumps marked (``evaluate --compare``).

    Parameters
    ----------
    path : Path
        The PNG.
    truth : Truth
        The truth they share.
    runs : sequence of (str, Evaluation)
        Label and evaluation of each estimate.
    """
    t0 = log_start(truth)
    fig, ax = plt.subplots(figsize=(WIDE_W, 2.6), dpi=DPI)
    errs = [np.hypot(ev.errors[:, 0], ev.errors[:, 1]) * 100.0 for _label, ev in runs]
    floor = log_floor(*errs)  # every error inside the axes (those under it drawn at it)
    # each kind of estimate in its colour, dashes and markers, as in summary.png (none an
    # event's colour): curves that coincide show
    styles = series_styles([label for label, _ev in runs], [e.size for e in errs])
    for (label, ev), err, style in zip(runs, errs, styles, strict=True):
        ax.plot(ev.assoc.t - t0, np.maximum(err, floor), lw=1.0, label=label, **style)
    ax.set_yscale("log")
    ax.set_ylim(bottom=floor)
    ax.set_ylabel("position error (cm)")
    ax.set_xlabel(TIME_LABEL)
    ax.grid(alpha=0.3, which="both")
    # right of the axes (none over the data)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    handles = mark_events([ax], truth, t0)
    log = log_name(truth.source)
    ax.set_title("position error against time" + (f": {log}" if log else ""), y=1.0)
    bottom = events_bottom(len(handles))
    fixed_layout(fig, LEFT, RIGHT + LEGEND_SIDE, bottom, TOP)
    events_legend(fig, ax, handles, bottom)
    _save(fig, path)


def draw_all(
    outdir: Path, truth: Truth, est: Estimate, ev: Evaluation, fgm: BeliefMap | None
) -> dict[str, str]:
    """Draw every figure the inputs allow into outdir; return {figure key: file name}."""
    out: dict[str, str] = {}
    fig1_paths(outdir / "fig1_paths.png", truth, est, fgm, ev.lamp_match, to_truth=ev.to_truth)
    out["fig1"] = "fig1_paths.png"
    fig3_errors(outdir / "fig3_errors.png", truth, ev)
    out["fig3"] = "fig3_errors.png"
    sets = fig4_sets(truth, est, ev)
    if sets:
        fig4_lamp_errors(
            outdir / "fig4_lamps.png",
            sets,
            max_dist=ev.metrics["params"]["lamp_max_dist_m"],
            noun=landmark_noun(truth)[:-1],
            run=run_title(truth, est),
        )
        out["fig4"] = "fig4_lamps.png"
    if fig_consistency(outdir / "consistency.png", truth, est, ev):
        out["consistency"] = "consistency.png"
    return out
