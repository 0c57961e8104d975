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
from numpy.typing import NDArray

from fuzzyslam.evaluation.core import Estimate, Evaluation, Truth
from fuzzyslam.evaluation.lamps import LampMatch
from fuzzyslam.figsave import (
    BLACK,
    BLUE,
    EVENT_COLOURS,
    EXPECTED,
    GREEN,
    ORANGE,
    PURPLE,
    SERIES,  # fmt: skip
    SERIES_DASHES,
    SKY,
    VERMILLION,
    fixed_layout,
    save_png,
)
from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.slam.health import chi2_quantile
from fuzzyslam.streams.logmeta import World

Array = NDArray[np.float64]
DPI = 120  # figures are made at their PNG's dpi: the layout's text sizes are the drawing's
C_TRUTH, C_EST, C_ODOM = BLACK, BLUE, VERMILLION  # the Okabe-Ito palette (figsave.py)


# Margins of the figures' fixed layouts (inches; fuzzyslam/figsave.py): tick labels and
# an axis label left, a title on top, tick labels and an axis label below (and the
# legend of the events 0.28 axes heights below the last axes); the blank rest is cropped.
# Titles are placed at y=1.0 (as matplotlib places them by default, above axes without
# top tick labels): otherwise it measures every y tick label at each draw to place them
LEFT, RIGHT, TOP, BOTTOM = 0.95, 0.25, 0.45, 0.65
EVENTS_BELOW = 0.28  # the events' legend: its top this far below the last axes (axes heights)
LEGEND_RIGHT = 3.6  # Fig. 1's legend right of the axes (its longest label, font size 8)
LEGEND_SIDE = 2.6  # consistency's and compare's legends right of their axes (font size 8)


EVENTS_HEIGHT = 0.4  # the events' legend: one row of font size 8, and a blank to spare


def _events_bottom(fig: plt.Figure, rows: int, gaps: float) -> float:
    """The bottom margin (inches) that holds the events' legend of :func:`_mark_events`
    under ``rows`` axes separated by ``gaps`` inches in all: the legend's top hangs
    EVENTS_BELOW axes heights below the last axes, whose height is
    h_a = (h - TOP - b - gaps) / rows, so b = EVENTS_HEIGHT + EVENTS_BELOW h_a gives
    b = (EVENTS_HEIGHT + k (h - TOP - gaps)) / (1 + k) with k = EVENTS_BELOW / rows
    (at least BOTTOM)."""
    h = fig.get_size_inches()[1]
    k = EVENTS_BELOW / rows
    return max(BOTTOM, (EVENTS_HEIGHT + k * (h - TOP - gaps)) / (1.0 + k))


def _save(fig: plt.Figure, path: Path) -> None:
    # one draw with the fixed layout, cropped to the drawn pixels (fuzzyslam/figsave.py)
    save_png(fig, path, DPI, tight=True)
    plt.close(fig)


def fig1_paths(
    path: Path,
    truth: Truth,
    est: Estimate,
    fgm: BeliefMap | None = None,
    lamp_match: LampMatch | None = None,
    title: str = "",
) -> None:
    """Fig. 1: true, estimated and odometry-only paths; true and estimated lamps (duplicated and
    missed ones marked when lamp_match is given); walls; the FGM underneath when given."""
    fig, ax = plt.subplots(figsize=(8.6 + LEGEND_RIGHT, 6.5), dpi=DPI)
    fixed_layout(fig, LEFT, LEGEND_RIGHT, 0.6, TOP)
    if fgm is not None:
        im = ax.imshow(
            fgm.pignistic_occupied(),
            origin="lower",
            extent=fgm.grid.extent,
            cmap="Greys",
            vmin=0.0,
            vmax=1.0,
            interpolation="nearest",
        )
        fig.colorbar(im, ax=ax, shrink=0.5, location="bottom", pad=0.1, label="FGM BetP(occupied)")
    world: World | None = truth.world
    if world is not None:
        for i, w in enumerate(world.wall_array):
            ax.plot(
                w[[0, 2]],
                w[[1, 3]],
                color="0.45" if fgm is None else "tab:olive",
                lw=1.2,
                label=("true walls" if i == 0 else None),
            )
    if est.odometry is not None:
        op = est.odometry[1]
        ax.plot(op[:, 0], op[:, 1], color=C_ODOM, lw=0.8, ls="--", label="odometry only")
    ax.plot(est.poses[:, 0], est.poses[:, 1], color=C_EST, lw=1.6, label=f"estimate ({est.label})")
    # the truth over the estimate, thin and dashed: where they agree both show
    ax.plot(truth.poses[:, 0], truth.poses[:, 1], color=C_TRUTH, lw=0.7, ls=(0, (4, 2)),
            label="true path", zorder=4)  # fmt: skip
    if world is not None and world.lamp_array.size:
        la = world.lamp_array
        ax.scatter(
            la[:, 0],
            la[:, 1],
            s=70,
            marker="o",
            facecolors="none",
            edgecolors=ORANGE,
            linewidths=1.5,
            label="true lamps",
            zorder=5,
        )
        for i, (x, y) in enumerate(la):
            ax.annotate(str(i), (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7)
    if est.landmarks is not None and est.landmarks.size:
        ax.scatter(
            est.landmarks[:, 0],
            est.landmarks[:, 1],
            s=40,
            marker="x",
            color=GREEN,
            linewidths=1.5,
            label="estimated lamps",
            zorder=6,
        )
        left = (  # the estimates the matching left over: (indices, size, colour, width, label)
            (lamp_match.spurious, 40, PURPLE, 1.5,
             f"spurious lamps ({{}}, > {lamp_match.max_dist:.2f} m from any)"),
            (lamp_match.duplicates, 90, VERMILLION, 2.0, "duplicated lamps ({})"),
        ) if lamp_match is not None else ()  # fmt: skip
        for idx, size, colour, width, label in left:
            if idx:
                d = est.landmarks[idx]
                ax.scatter(d[:, 0], d[:, 1], s=size, marker="x", color=colour,
                           linewidths=width, label=label.format(len(d)), zorder=7)  # fmt: skip
        if lamp_match is not None and lamp_match.missed and world is not None:
            m = world.lamp_array[lamp_match.missed]
            ax.scatter(
                m[:, 0],
                m[:, 1],
                s=110,
                marker="s",
                facecolors="none",
                edgecolors=VERMILLION,
                linewidths=1.5,
                label=f"missed lamps ({len(m)})",
                zorder=7,
            )
    ax.scatter(*truth.poses[0, :2], s=60, marker="*", color="k", zorder=7, label="start")
    pts = [truth.poses[:, :2], est.poses[:, :2]]
    if world is not None:
        pts.append(world.wall_array.reshape(-1, 2))
    if est.odometry is not None:
        pts.append(est.odometry[1][:, :2])
    if fgm is not None:
        e = fgm.grid.extent
        pts.append(np.array([[e[0], e[2]], [e[1], e[3]]]))
    allp = np.vstack(pts)
    lo, hi = allp.min(axis=0), allp.max(axis=0)
    pad = 0.04 * float(np.max(hi - lo)) + 0.1
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(
        title or f"Fig. 1: {'FGM, ' if fgm is not None else ''}paths and lamps (map frame)",
        y=1.0,
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, framealpha=0.85)
    _save(fig, path)


def _mark_events(axes: list[plt.Axes], truth: Truth) -> None:
    """Vertical lines at run starts (labelled), the FGM freeze, lamp failures and bumps, with a
    legend of the event kinds on the last axis."""
    if truth.scenario is None:
        return
    from matplotlib.lines import Line2D

    style = {
        "run start": {"color": "0.6", "lw": 0.8, "ls": ":"},
        "FGM frozen": {"color": EVENT_COLOURS["FGM frozen"], "lw": 1.2, "ls": "-"},
        "lamp failure": {"color": EVENT_COLOURS["lamp failure"], "lw": 1.2, "ls": "--"},
        "bump": {"color": EVENT_COLOURS["bump"], "lw": 1.0, "ls": "-."},
    }
    times: dict[str, list[float]] = {k: [] for k in style}
    for r, t0, _t1 in truth.scenario.run_intervals():
        times["run start"].append(t0)
        axes[0].annotate(
            f"run {r}",
            (t0, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(2, -10),
            textcoords="offset points",
            fontsize=7,
        )
    for e in truth.scenario.events:
        if e.kind == "lamp_failure":
            times["lamp failure"].append(e.t)
        elif e.kind == "bump":
            times["bump"].append(e.t)
    if truth.freeze_run is not None:
        t_freeze = truth.scenario.run_end_time(truth.freeze_run)
        if t_freeze is not None:
            times["FGM frozen"].append(t_freeze)
    handles = []
    for kind, ts in times.items():
        for t in ts:
            for ax in axes:
                ax.axvline(t, **style[kind])
        if ts:
            handles.append(Line2D([], [], label=f"{kind} ({len(ts)})", **style[kind]))
    if handles:
        leg = axes[-1].get_legend()
        axes[-1].legend(
            handles=handles,
            loc="upper center",
            bbox_to_anchor=(0.5, -EVENTS_BELOW),
            fontsize=8,
            ncol=len(handles),
            frameon=False,
        )
        if leg is not None:
            axes[-1].add_artist(leg)


def fig3_errors(path: Path, truth: Truth, ev: Evaluation, title: str = "") -> None:
    """Fig. 3: x, y (cm) and heading (deg) errors against time, +-2 sigma from the covariance,
    run boundaries, the FGM freeze, lamp failures and bumps marked."""
    t = ev.assoc.t
    fig, axes = plt.subplots(3, 1, figsize=(10, 7.5), sharex=True, dpi=DPI)
    scale = [100.0, 100.0, 180.0 / np.pi]
    names = ["x error (cm)", "y error (cm)", "heading error (deg)"]
    for k, ax in enumerate(axes):
        e = ev.errors[:, k] * scale[k]
        if ev.sigma is not None:
            s2 = 2.0 * ev.sigma[:, k] * scale[k]
            ax.fill_between(t, -s2, s2, color=C_EST, alpha=0.18, lw=0, label="+-2 sigma (filter)")
        ax.plot(t, e, color=C_EST, lw=0.8, label="estimate - truth")
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
    _mark_events(list(axes), truth)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[-1].set_xlabel("time (s)")
    axes[0].set_title(title or "Fig. 3: pose errors against time", y=1.0)
    fixed_layout(fig, LEFT, RIGHT, _events_bottom(fig, 3, 2 * 0.22), TOP, hspace=0.22)
    _save(fig, path)


def fig4_lamp_errors(
    path: Path, per_lamp: Mapping[str, Array], title: str = "", max_dist: float | None = None
) -> None:
    """Fig. 4: position error of each true lamp (cm), one bar group per lamp, one bar per
    labelled estimate (e.g. end of run 4, end of run 6, with bumps). Missed lamps: a cross."""
    fig, ax = plt.subplots(figsize=(10, 4), dpi=DPI)
    labels = list(per_lamp)
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
            ax.scatter(
                pos[miss],
                np.zeros(miss.sum()),
                marker="x",
                color=bars.patches[0].get_facecolor(),
                s=40,
                zorder=5,
            )
    ax.set_xticks(x)
    ax.set_xticklabels([str(i) for i in x])
    ax.set_xlabel(
        f"true lamp index (x on the axis: lamp not matched within {max_dist * 100:.0f} cm)"
        if max_dist
        else "true lamp index"
    )
    ax.set_ylabel("lamp position error (cm)")
    ax.set_title(title or "Fig. 4: per-lamp position error", y=1.0)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    fixed_layout(fig, LEFT, RIGHT, BOTTOM, TOP)
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
    """The lower limit of a log axis that shows every positive finite value: the power of
    ten at or below the smallest (1e-3 without one).

    Parameters
    ----------
    *values : ndarray
        The values drawn.

    Returns
    -------
    float
    """
    pos = [v[np.isfinite(v) & (v > 0)] for v in (np.asarray(x, dtype=float) for x in values)]
    pos = [p for p in pos if p.size]
    if not pos:
        return 1e-3
    return float(10.0 ** np.floor(np.log10(min(float(p.min()) for p in pos))))


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


def fig_consistency(path: Path, truth: Truth, est: Estimate, ev: Evaluation) -> bool:
    """NEES (3 dof) against time with its per-sample 95 % band, and NIS of accepted updates
    per kind, normalised by dof. Returns False (nothing drawn) without covariance or updates."""
    has_nis = est.updates is not None and est.updates.t.size > 0
    if ev.nees is None and not has_nis:
        return False
    fig, axes = plt.subplots(2, 1, figsize=(10 + LEGEND_SIDE, 6), sharex=True, dpi=DPI)
    ax = axes[0]
    side = {"loc": "upper left", "bbox_to_anchor": (1.01, 1.0), "fontsize": 8, "frameon": False}
    if ev.nees is not None:
        lo, hi = chi2_quantile(0.025, 3), chi2_quantile(0.975, 3)
        floor = log_floor(ev.nees)  # every sample inside the axes (zeros drawn at it)
        ax.semilogy(
            ev.assoc.t,
            np.maximum(ev.nees, floor),
            color=SKY,
            lw=0.5,
            label=f"NEES (mean {np.nanmean(ev.nees):.2f})",
        )
        ax.semilogy(
            ev.assoc.t,
            running_mean(ev.nees),
            color=BLUE,
            lw=1.4,
            label="running mean (2 % of samples)",
        )
        ax.axhspan(lo, hi, color=ORANGE, alpha=0.15, lw=0, label="95 % band, one sample (3 dof)")
        ax.axhline(3.0, color=EXPECTED, lw=0.9, ls="--", label="expected NEES = 3")
        ax.set_ylim(bottom=min(floor, 10.0 ** np.floor(np.log10(lo))))
        ax.legend(**side)
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
        floor = log_floor(*(v for _k, _m, v in kinds))
        for j, (kind, m, v) in enumerate(kinds):
            colour = SERIES[j % len(SERIES)]
            ax.semilogy(u.t[m], np.maximum(v, floor), ".", ms=2, alpha=0.5, color=colour,
                        label=f"{kind} ({m.sum()} accepted, mean {v.mean():.2f})")  # fmt: skip
            ax.semilogy(u.t[m], running_mean(v), color=colour, lw=1.4,
                        ls=SERIES_DASHES[j % len(SERIES_DASHES)],
                        label=f"{kind}, running mean")  # fmt: skip
        ax.axhline(1.0, color=EXPECTED, lw=0.9, ls="--", label="expected NIS / dof = 1")
        ax.set_ylim(bottom=min(floor, 0.1))
        ax.legend(**side, markerscale=4)
    ax.set_ylabel("NIS / dof (dimensionless)")
    ax.set_xlabel("time (s)")
    ax.grid(alpha=0.3, which="both")
    _mark_events(list(axes), truth)
    axes[0].set_title("Filter consistency against truth (NEES) and innovations (NIS)", y=1.0)
    bottom = _events_bottom(fig, 2, 0.28)
    fixed_layout(fig, LEFT, RIGHT + LEGEND_SIDE, bottom, TOP, hspace=0.28)
    _save(fig, path)
    return True


def fig4_sets(truth: Truth, est: Estimate, ev: Evaluation) -> dict[str, Array]:
    """Per-lamp errors to draw in Fig. 4: the map at the end of the FGM-freeze run and of the
    last run (the paper's 'run 4' and 'run 6') when snapshots exist, else the final map."""
    by_run = ev.lamp_match_by_run
    if by_run:
        last = max(by_run)
        runs = sorted({r for r in (truth.freeze_run, last) if r is not None and r in by_run})
        return {f"{est.label}, end of run {r}": by_run[r].per_true for r in runs}
    if ev.lamp_match is not None:
        return {f"{est.label}, final map": ev.lamp_match.per_true}
    return {}


def fig_compare(path: Path, truth: Truth, runs: Sequence[tuple[str, Evaluation]]) -> None:
    """Position error (cm, log scale) against time of several estimates of one truth, with
    the run boundaries, the FGM freeze, lamp failures and bumps marked (``evaluate
    --compare``)."""
    fig, ax = plt.subplots(figsize=(10 + LEGEND_SIDE, 4.2), dpi=DPI)
    errs = [np.hypot(ev.errors[:, 0], ev.errors[:, 1]) * 100.0 for _label, ev in runs]
    floor = log_floor(*errs)  # every error inside the axes (zeros drawn at it)
    for j, ((label, ev), err) in enumerate(zip(runs, errs, strict=True)):
        # the palette's colours, none an event's, and dashes: curves that coincide show
        ax.plot(ev.assoc.t, np.maximum(err, floor), lw=1.0, color=SERIES[j % len(SERIES)],
                ls=SERIES_DASHES[j % len(SERIES_DASHES)], label=label)  # fmt: skip
    ax.set_yscale("log")
    ax.set_ylim(bottom=floor)
    ax.set_ylabel("position error (cm)")
    ax.set_xlabel("time (s)")
    ax.grid(alpha=0.3, which="both")
    # right of the axes (none over the data); first: _mark_events keeps it beside its own
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    _mark_events([ax], truth)
    ax.set_title("position error against time, side by side", y=1.0)
    fixed_layout(fig, LEFT, RIGHT + LEGEND_SIDE, _events_bottom(fig, 1, 0.0), TOP)
    _save(fig, path)


def draw_all(
    outdir: Path, truth: Truth, est: Estimate, ev: Evaluation, fgm: BeliefMap | None
) -> dict[str, str]:
    """Draw every figure the inputs allow into outdir; return {figure key: file name}."""
    out: dict[str, str] = {}
    fig1_paths(outdir / "fig1_paths.png", truth, est, fgm, ev.lamp_match)
    out["fig1"] = "fig1_paths.png"
    fig3_errors(outdir / "fig3_errors.png", truth, ev)
    out["fig3"] = "fig3_errors.png"
    sets = fig4_sets(truth, est, ev)
    if sets:
        fig4_lamp_errors(
            outdir / "fig4_lamps.png", sets, max_dist=ev.metrics["params"]["lamp_max_dist_m"]
        )
        out["fig4"] = "fig4_lamps.png"
    if fig_consistency(outdir / "consistency.png", truth, est, ev):
        out["consistency"] = "consistency.png"
    return out
