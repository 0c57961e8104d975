"""One figure per swept key of a ``fuzzyslam sweep``: each measure against the key's values.

A figure has a panel per measure (its name and unit on the y axis); the key's values go on
the x axis (a number line when they are all numbers, else one tick per value). A marker is
the mean over seeds (or logs) of a grid point, its bar the min-max range; with more than
one swept key, each combination of the other keys' values is a line of its own (legend).
Colours are the Okabe-Ito palette, also told apart by marker shape (colour-blind safe).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from fuzzyslam.figsave import OKABE_ITO  # the figures' one palette (Okabe-Ito)
from fuzzyslam.fileio import atomic_path

DPI = 150
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
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


def figure_name(key: str) -> str:
    """File name of the figure of swept ``key``: ``sweep_KEY.png`` (a safe file name)."""
    return f"sweep_{re.sub(r'[^A-Za-z0-9_.-]', '_', key)}.png"


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
        xpos = {v: (v if numeric else j) for j, v in enumerate(values)}
        others = [k for k in keys if k != key]
        groups: dict[tuple, list[dict]] = {}
        for r in rows:
            groups.setdefault(tuple(r["values"][k] for k in others), []).append(r)
        fig, axes = plt.subplots(1, max(len(measures), 1), figsize=(4.6 * len(measures), 4.0),
                                 squeeze=False)  # fmt: skip
        for ax, m in zip(axes[0], measures, strict=False):
            for g, (combo, members) in enumerate(groups.items()):
                pts = [(xpos[r["values"][key]], r["measures"][m]) for r in members
                       if r["measures"][m]["n"]]  # fmt: skip
                pts.sort(key=lambda p: p[0])
                if not pts:
                    continue
                x = [p[0] for p in pts]
                mean = [p[1]["mean"] for p in pts]
                err = [[p[1]["mean"] - p[1]["min"] for p in pts],
                       [p[1]["max"] - p[1]["mean"] for p in pts]]  # fmt: skip
                label = ", ".join(f"{k}={v}" for k, v in zip(others, combo, strict=True))
                ax.errorbar(x, mean, yerr=err, color=OKABE_ITO[g % len(OKABE_ITO)],
                            marker=MARKERS[g % len(MARKERS)], capsize=4, linewidth=1.5,
                            label=label or None)  # fmt: skip
            ax.set_xlabel(key_label(key))
            ax.set_ylabel(m)
            ax.set_ylim(bottom=0)
            ax.grid(True, alpha=0.3)
            if not numeric:
                ax.set_xticks(range(len(values)), [str(v) for v in values])
            if others and len(groups) > 1:
                ax.legend(fontsize=8)
        fig.suptitle(f"Sweep of {key}: mean over {n} {over}, bars min to max")
        fig.tight_layout()
        path = root / figure_name(key)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=DPI)
        plt.close(fig)
        out.append(path)
    return out
