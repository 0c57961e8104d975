"""Preview picture of a simulation: walls, lamps (lit / failed), true and dead-reckoning paths."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from fuzzyslam.figsave import (
    BLACK,
    BLUE,
    COLUMN_W,
    GREEN,
    PRINT_DPI,
    PURPLE,
    VERMILLION,
    YELLOW,
    fixed_layout,
    save_png,
    styled,
)
from fuzzyslam.fileio import atomic_path
from fuzzyslam.sim.scenario import Plan, lamps_lit

LEFT, RIGHT, TOP, BOTTOM = 0.55, 0.1, 0.3, 0.42  # inches (8-9 pt text)
LEGEND_ROW = 0.155  # inches, one row of the legend below the axes


@styled
def save_preview(plan: Plan, path: str | os.PathLike, title: str = "") -> None:
    """Write a PNG of the world and the paths (atomic), one column wide.

    Parameters
    ----------
    plan : Plan
        The simulation's plan.
    path : path
        The PNG.
    title : str
        The figure's title.
    """
    world, dr, enc = plan.world, plan.drive, plan.encoders
    walls = world.wall_array
    pts = np.vstack([walls.reshape(-1, 2), dr.pose[:, :2], enc.dead_reckoning[:, :2]])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.03 * float(np.max(hi - lo)) + 0.1
    lo, hi = lo - pad, hi + pad
    ax_w = COLUMN_W - LEFT - RIGHT
    ax_h = ax_w * float(np.clip((hi[1] - lo[1]) / (hi[0] - lo[0]), 0.4, 1.3))
    fig, ax = plt.subplots(figsize=(COLUMN_W, 1.0), dpi=PRINT_DPI)  # its height set below
    for i, (x0, y0, x1, y1) in enumerate(walls):
        ax.plot([x0, x1], [y0, y1], color="0.3", lw=1.5, label="walls" if i == 0 else None)
    ax.plot(dr.pose[:, 0], dr.pose[:, 1], color=BLUE, lw=1.0, label="true path")
    ax.plot(*enc.dead_reckoning[:, :2].T, color=VERMILLION, lw=1.0, ls="--",
            label="dead reckoning")  # fmt: skip
    lamps = world.lamp_array
    lit_end = lamps_lit(plan.events, len(lamps), dr.duration)
    ax.scatter(*lamps[lit_end].T, s=30, c=YELLOW, edgecolors=BLACK, linewidths=0.8,
               label="lamp", zorder=3)  # fmt: skip
    if (~lit_end).any():
        ax.scatter(*lamps[~lit_end].T, s=30, c="0.6", marker="X", edgecolors=BLACK,
                   linewidths=0.5, label="lamp (failed)", zorder=3)  # fmt: skip
    for i, (x, y) in enumerate(lamps):
        ax.annotate(str(i), (x, y), textcoords="offset points", xytext=(3, 3), fontsize=7)
    ax.plot(*plan.start_pose[:2], "o", color=GREEN, mec=BLACK, mew=0.6, ms=6, label="start",
            zorder=5)  # fmt: skip
    bumps = [e for e in plan.events if e.kind == "bump"]
    if bumps:  # over the lamps, with a legend entry
        k = np.minimum(np.round(np.array([e.t for e in bumps]) / dr.dt).astype(int),
                       len(dr.pose) - 1)  # fmt: skip
        ax.plot(dr.pose[k, 0], dr.pose[k, 1], "*", color=PURPLE, mec=BLACK, mew=0.5, ms=10,
                ls="none", label=f"bump ({len(bumps)})", zorder=6)  # fmt: skip
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or "simulated world", y=1.0)
    ax.grid(alpha=0.3)
    n = len(ax.get_legend_handles_labels()[0])
    bottom = BOTTOM + -(-n // 3) * LEGEND_ROW + 0.05
    fig.set_size_inches(COLUMN_W, TOP + ax_h + bottom)
    fixed_layout(fig, LEFT, RIGHT, bottom, TOP)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -BOTTOM / ax_h), ncol=3, frameon=False,
              borderaxespad=0.0, columnspacing=0.8, handlelength=1.6)  # fmt: skip
    with atomic_path(path) as tmp:
        save_png(fig, tmp, PRINT_DPI, tight=True)
    plt.close(fig)
