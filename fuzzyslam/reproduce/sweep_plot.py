"""One figure per swept key of a ``fuzzyslam sweep``: each measure against the key's values.

A figure has a panel per measure (its name and unit on the y axis); the key's values go on
the x axis (a number line when they are all numbers, else one tick per value: booleans and
strings are categories, drawn as points without a joining line). A marker is the mean over
seeds (or logs) of a grid point, its bar the min-max range; with more than one swept key,
each combination of the other keys' values is a line of its own, in one legend for the
figure between its title and its panels.
Colours are the Okabe-Ito palette, also told apart by marker shape (colour-blind safe).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import matplotlib.ticker

from fuzzyslam.figsave import (  # the figures' one palette (Okabe-Ito) and style
    OKABE_ITO,
    PRINT_DPI,
    WIDE_W,
    fixed_layout,
    save_png,
    styled,
)
from fuzzyslam.fileio import atomic_path

DPI = PRINT_DPI
PANEL_W, PANEL_H = 1.65, 1.5  # inches; the panels side by side, at most WIDE_W in all
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
TITLE_ROOM = 0.3  # inches over the panels: the title
LEGEND_ROW = 0.17  # one row of the figure's legend (8 pt, with its markers)
LEGEND_COLS = 3  # the legend's columns (the other keys' values)
Y_MARGIN = 0.08  # room over the highest mark (of the y range)
CATEGORY_DODGE = 0.12  # the groups' points side by side at a category (tick spacing 1)
# unit of a config key by its name's ending (the config's naming convention)
SUFFIX_UNITS = {"_deg": "deg", "_m": "m", "_s": "s", "_hz": "Hz", "_px": "px", "_cm": "cm"}


def config_unit(key: str) -> str | None:
    """The unit of a dotted config key (``robot.wheel_noise``) from its field's
    ``metadata["unit"]`` in the config's dataclasses; None when the field gives none (or
    the key names no field).

    Parameters
    ----------
    key : str
        The dotted key.

    Returns
    -------
    str or None
    """
    import dataclasses
    import typing

    from fuzzyslam.config import Config

    cls: Any = Config
    field = None
    for part in key.split("."):
        if not dataclasses.is_dataclass(cls):
            return None
        fields = {f.name: f for f in dataclasses.fields(cls)}
        if part not in fields:
            return None
        field = fields[part]
        cls = typing.get_type_hints(cls).get(part)
    return field.metadata.get("unit") if field is not None else None


def key_label(key: str) -> str:
    """Axis label of a config key: its name with its unit, from the config's metadata
    (:func:`config_unit`), else from its name's ending; the name alone without one.

    Parameters
    ----------
    key : str
        The dotted key.

    Returns
    -------
    str
    """
    unit = config_unit(key)
    if unit is None:
        unit = next((u for suffix, u in SUFFIX_UNITS.items() if key.endswith(suffix)), None)
    return f"{key} ({unit})" if unit else key


def _numeric(values: list[Any]) -> bool:
    return all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)


def legend_rows_of(entries: int) -> int:
    """Rows of the figure's legend of ``entries`` lines, :data:`LEGEND_COLS` a row."""
    return -(-entries // LEGEND_COLS)


def figure_name(key: str) -> str:
    """File name of the figure of swept ``key``: ``sweep_KEY.png`` (a safe file name)."""
    return f"sweep_{re.sub(r'[^A-Za-z0-9_.-]', '_', key)}.png"


def log_x(values: list[Any]) -> bool:
    """A logarithmic x axis for the swept values: all positive numbers spanning more than
    a decade.

    Parameters
    ----------
    values : list
        The swept values.

    Returns
    -------
    bool
    """
    if not values or not _numeric(values):
        return False
    lo, hi = min(values), max(values)
    return lo > 0 and hi / lo > 10.0


def tick_text(v: Any) -> str:
    """A swept value as its tick's text (``0.005``, ``2``, ``1e-05``: :func:`repr`'s
    shortest form for numbers).

    Parameters
    ----------
    v : any
        The value.

    Returns
    -------
    str
    """
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


@styled
def plot_sweep(root: Path, rows: list[dict], keys: list[str], n: int, over: str) -> list[Path]:
    """Draw ``root/sweep_KEY.png`` for every swept key (written atomically).

    Parameters
    ----------
    root : Path
        The sweep's output directory.
    rows : list of dict
        The table rows (``values``: key -> value; ``measures``: name -> mean, min, max, n).
    keys : list of str
        The swept keys, in the order given.
    n : int
        Seeds (or logs) per grid point, for the caption.
    over : str
        What the statistics are over: "seeds" or "logs".

    Returns
    -------
    list of Path
        The figures written, one per key.
    """
    measures = list(rows[0]["measures"]) if rows else []
    out = []
    for key in keys:
        values = list(dict.fromkeys(r["values"][key] for r in rows))
        numeric = _numeric(values)
        if not numeric and all(isinstance(v, bool) for v in values):
            values.sort()  # False, True
        xpos = {v: (v if numeric else j) for j, v in enumerate(values)}
        others = [k for k in keys if k != key]
        groups: dict[tuple, list[dict]] = {}
        for r in rows:
            groups.setdefault(tuple(r["values"][k] for k in others), []).append(r)
        legend_rows = legend_rows_of(len(groups)) if others and len(groups) > 1 else 0
        left, right, wgap, hgap, bottom = 0.6, 0.15, 0.65, 0.6, 0.45
        top = TITLE_ROOM + legend_rows * LEGEND_ROW + (0.1 if legend_rows else 0.0)
        cols = max(len(measures), 1)
        while cols > 1 and left + right + cols * PANEL_W + (cols - 1) * wgap > WIDE_W:
            cols -= 1  # too many measures for one row: more rows
        nrows = -(-max(len(measures), 1) // cols)
        fig, axes = plt.subplots(
            nrows,
            cols,
            figsize=(left + right + cols * PANEL_W + (cols - 1) * wgap,
                     top + bottom + nrows * PANEL_H + (nrows - 1) * hgap),
            squeeze=False,
            dpi=DPI,
        )  # fmt: skip
        for ax in axes.ravel()[len(measures) :]:
            ax.set_axis_off()
        handles: dict[str, Any] = {}  # one legend for the figure: label -> handle
        for ax, m in zip(axes.ravel(), measures, strict=False):
            highest = 0.0
            for g, (combo, members) in enumerate(groups.items()):
                pts = [(xpos[r["values"][key]], r["measures"][m]) for r in members
                       if r["measures"][m]["n"]]  # fmt: skip
                pts.sort(key=lambda p: p[0])
                if not pts:
                    continue
                # categories: the groups' points side by side around their value's tick
                dodge = 0.0 if numeric else CATEGORY_DODGE * (g - (len(groups) - 1) / 2.0)
                x = [p[0] + dodge for p in pts]
                mean = [p[1]["mean"] for p in pts]
                err = [[p[1]["mean"] - p[1]["min"] for p in pts],
                       [p[1]["max"] - p[1]["mean"] for p in pts]]  # fmt: skip
                highest = max(highest, *(p[1]["max"] for p in pts), *mean)
                label = ", ".join(f"{k}={v}" for k, v in zip(others, combo, strict=True))
                # a line joins the values of a number line only: categories are points
                drawn = ax.errorbar(x, mean, yerr=err, color=OKABE_ITO[g % len(OKABE_ITO)],
                                    marker=MARKERS[g % len(MARKERS)], capsize=3,
                                    linewidth=1.2, linestyle="-" if numeric else "none",
                                    label=label or None)  # fmt: skip
                if label:
                    handles.setdefault(label, drawn)
            ax.set_xlabel(key_label(key))
            ax.set_ylabel(m)
            # from 0, a margin over the highest mark (no marker cut by the spine)
            ax.set_ylim(0.0, highest * (1.0 + Y_MARGIN) if highest > 0 else 1.0)
            ax.grid(True, alpha=0.3)
            # ticks at the swept values only (a log axis when they span over a decade)
            if log_x(values):
                ax.set_xscale("log")
                ax.minorticks_off()
            if numeric:
                ax.set_xticks(values, [tick_text(v) for v in values])
                ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
            else:
                ax.set_xticks(range(len(values)), [str(v) for v in values])
                ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
                ax.set_xlim(-0.5, len(values) - 0.5)
            if numeric and len(values) > 1:
                lo, hi = min(values), max(values)
                if log_x(values):
                    ax.set_xlim(lo / (hi / lo) ** 0.08, hi * (hi / lo) ** 0.08)
                else:
                    ax.set_xlim(lo - 0.08 * (hi - lo), hi + 0.08 * (hi - lo))
        unit = over if n != 1 else over.removesuffix("s")
        fig.suptitle(f"Sweep of {key}: mean over {n} {unit}, bars min to max", y=1.0,
                     va="top", x=0.02, ha="left")  # fmt: skip
        if legend_rows:
            # one legend for the figure, between the title and the panels (over no data)
            h = fig.get_size_inches()[1]
            fig.legend(list(handles.values()), list(handles), loc="upper left",
                       bbox_to_anchor=(left / fig.get_size_inches()[0], 1.0 - TITLE_ROOM / h),
                       ncol=LEGEND_COLS, frameon=False, borderaxespad=0.0)  # fmt: skip
        fixed_layout(fig, left, right, bottom, top, hspace=hgap, wspace=wgap)
        path = root / figure_name(key)
        with atomic_path(path) as tmp:
            save_png(fig, tmp, DPI, tight=True)
        plt.close(fig)
        out.append(path)
    return out
