"""Preview picture of a simulation: walls, lamps (lit / failed), true and dead-reckoning paths."""

from __future__ import annotations

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from fuzzyslam.fileio import atomic_path
from fuzzyslam.sim.scenario import Plan, lamps_lit


def save_preview(plan: Plan, path: str | os.PathLike, title: str = "") -> None:
    """Write a PNG of the world and the paths (atomic).

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
    fig, ax = plt.subplots(figsize=(9, 6), dpi=110)
    for x0, y0, x1, y1 in world.wall_array:
        ax.plot([x0, x1], [y0, y1], color="k", lw=2)
    lamps = world.lamp_array
    lit_end = lamps_lit(plan.events, len(lamps), dr.duration)
    ax.scatter(*lamps[lit_end].T, s=60, c="gold", edgecolors="k", label="lamp", zorder=3)
    if (~lit_end).any():
        ax.scatter(*lamps[~lit_end].T, s=60, c="0.6", marker="X", label="lamp (failed)", zorder=3)
    for i, (x, y) in enumerate(lamps):
        ax.annotate(str(i), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.plot(dr.pose[:, 0], dr.pose[:, 1], color="tab:blue", lw=1, label="true path")
    ax.plot(*enc.dead_reckoning[:, :2].T, color="tab:red", lw=0.8, label="dead reckoning")
    ax.plot(*plan.start_pose[:2], "go", label="start")
    for e in plan.events:
        if e.kind == "bump":
            k = round(e.t / dr.dt)
            ax.plot(*dr.pose[min(k, len(dr.pose) - 1), :2], "m*", ms=10)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title or "simulated world")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
