"""Matplotlib figures written as PNG files with one draw and no text measuring (the
stages' figures).

``Figure.savefig(..., bbox_inches="tight")`` draws a figure twice (once with drawing
disabled, to find the tight bounding box, then for real), ``tight_layout`` measures every
tick label and title once more before that, and PIL compresses the RGBA picture at zlib
level 6. Here a figure is laid out with fixed margins in inches (:func:`fixed_layout`,
sized for the labels the stages draw), drawn once on the Agg canvas, and cropped to the
pixels that differ from the figure's background, ``savefig.pad_inches`` around them: the
blank part of the generous margins goes, and only the legends are measured. When a drawn
pixel touches the canvas's edge or a legend leaves it (an artist is cut, or lies wholly
beyond) it falls back to ``savefig(bbox_inches="tight")``, which grows the canvas. The
picture is written as RGB (the figures are opaque) at a lower zlib level.
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
from collections.abc import Callable, Sequence
from typing import ParamSpec, TypeVar

import matplotlib
import matplotlib.style
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_rgba_array
from matplotlib.figure import Figure

P = ParamSpec("P")
R = TypeVar("R")

# The figures' one palette: Okabe & Ito (2008), "Color Universal Design", told apart with
# any colour vision (tab10's orange and green are not, for deuteranopes). SERIES colours
# the curves of a plot, in order, with SERIES_DASHES where curves overlap; the events
# marked across plots (fig3, compare, consistency) keep colours of their own, none of
# them a curve's; EXPECTED draws an expected value (black, dashed).
OKABE_ITO = ("#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00", "#F0E442",
             "#000000")  # fmt: skip
BLUE, ORANGE, GREEN, PURPLE, SKY, VERMILLION, YELLOW, BLACK = OKABE_ITO
SERIES = (BLUE, ORANGE, SKY, BLACK)
SERIES_DASHES = ("-", "--", "-.", ":")
EVENT_COLOURS = {"FGM frozen": GREEN, "lamp failure": VERMILLION, "bump": PURPLE}
EXPECTED = BLACK

# The kinds of estimate the figures put side by side (summary.png, compare.png): one
# colour, line style and marker each, the same in every figure. An estimate's kind is
# found in its label (:func:`estimate_kind`); labels of no kind take the series' other
# colours, in order (:func:`series_styles`). Markers every few samples (KIND_MARKERS
# along a curve) tell apart curves that coincide. The odometry is fig1's dead reckoning.
ESTIMATE_KINDS = {  # kind: (words in a label that name it, style)
    "lamps only": (("lamps only", "no fixes"), {"color": BLUE, "ls": "-", "marker": None}),
    "heading fixes": (("heading fixes", "heading fix"),
                      {"color": ORANGE, "ls": "--", "marker": "^"}),
    "pose fixes": (("pose fixes", "pose fix"), {"color": SKY, "ls": "-.", "marker": "o"}),
    "odometry": (("odometry", "dead reckoning"), {"color": VERMILLION, "ls": "--",
                                                  "marker": None}),
}  # fmt: skip
KIND_MARKERS = 14  # markers along a curve that has them (markevery)


def estimate_kind(label: str) -> str | None:
    """The kind of estimate a label names (a key of :data:`ESTIMATE_KINDS`): the first
    kind whose words it holds (case ignored), None for none.

    Parameters
    ----------
    label : str
        The estimate's label ("all lamps off: heading fixes", "lamps only (A, B)").

    Returns
    -------
    str or None
    """
    low = label.lower()
    return next((k for k, (words, _s) in ESTIMATE_KINDS.items()
                 if any(w in low for w in words)), None)  # fmt: skip


def series_styles(labels: Sequence[str], samples: Sequence[int] | None = None) -> list[dict]:
    """The line style of each labelled estimate, for ``Axes.plot``: its kind's
    (:data:`ESTIMATE_KINDS`), or, for a label of no kind, the next of the series' colours
    and dashes that no kind drawn uses.

    Parameters
    ----------
    labels : sequence of str
        The estimates' labels, in drawing order.
    samples : sequence of int, optional
        The samples of each curve: a kind's markers go every ``n / KIND_MARKERS``
        samples, shifted per kind (coinciding curves' markers side by side).

    Returns
    -------
    list of dict
        ``color``, ``ls``, ``marker``, ``markevery``, ``ms`` and ``zorder`` for each
        label.
    """
    kinds = [estimate_kind(lab) for lab in labels]
    used = {ESTIMATE_KINDS[k][1]["color"] for k in kinds if k is not None}
    # black first (no kind's, no event's), then the series' colours no kind drawn uses
    order = [BLACK, *(c for c in SERIES if c != BLACK)]
    dashes = dict(zip(order, SERIES_DASHES, strict=True))
    free = [(c, dashes[c]) for c in order if c not in used]
    rank = {k: r for r, k in enumerate(ESTIMATE_KINDS)}
    out, j = [], 0
    for i, k in enumerate(kinds):
        if k is not None:
            style = dict(ESTIMATE_KINDS[k][1])
        else:
            colour, dash = free[j % len(free)] if free else (SERIES[j % len(SERIES)], "-")
            style = {"color": colour, "ls": dash, "marker": None}
            j += 1
        # the kinds in their order, lamps only lowest: the same curve on top everywhere
        style["zorder"] = 2.0 + 0.01 * (rank[k] if k is not None else len(rank) + j)
        n = samples[i] if samples is not None else 0
        step = max(n // KIND_MARKERS, 1)
        shift = rank[k] if k is not None else 0
        style["markevery"] = (shift * step // 3, step) if style["marker"] and n else None
        style["ms"] = 3.5
        out.append(style)
    return out


# The figures' one style, at print size: a figure is drawn at its printed width (one
# column, COLUMN_W, or both, WIDE_W: a two-column paper's widths), its text 8-9 pt, its
# lines at least 1 pt, and written at PRINT_DPI (about 300 dots per inch in print).
COLUMN_W = 3.5  # inches: a single column (8.9 cm)
WIDE_W = 7.2  # inches: both columns (18.3 cm), the widest a figure is
PRINT_DPI = 300
STYLE = {
    "font.size": 8.0,
    "axes.titlesize": 9.0,
    "axes.labelsize": 8.0,
    "xtick.labelsize": 8.0,
    "ytick.labelsize": 8.0,
    "legend.fontsize": 8.0,
    "figure.titlesize": 9.0,
    "lines.linewidth": 1.2,
    "lines.markersize": 5.0,
    "axes.linewidth": 0.8,
    "grid.linewidth": 0.5,
    "xtick.major.width": 0.8,
    "ytick.major.width": 0.8,
    "legend.handlelength": 2.2,
    "legend.borderaxespad": 0.3,
    "savefig.pad_inches": 0.03,
    "image.interpolation": "nearest",
}
MIN_LW = 1.0  # the thinnest line of data (pt)

COMPRESS_LEVEL = 3  # zlib: 6 (PIL's default) costs 1.5x the time for files 5-8 % smaller
SOFTWARE = f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/"


def figure_style() -> contextlib.AbstractContextManager:
    """The figures' one style (:data:`STYLE`: font sizes, line widths) on matplotlib's
    defaults, as a context: a figure is made, drawn and saved inside it (tick labels are
    made at the draw).

    The style starts from matplotlib's own defaults, not from the user's settings (a
    ``matplotlibrc`` in MPLCONFIGDIR, MATPLOTLIBRC or the working directory: fonts, grid,
    colours, line widths), so that the same inputs give the same PNG bytes anywhere.
    Matplotlib's ``"default"`` style sets every setting of the picture and leaves those
    of the session alone (backend, interactive, toolbar, ...): the figure process forked
    by a run (``forked.py``) keeps its canvas.

    Returns
    -------
    context manager
        ``matplotlib.style.context(["default", STYLE])``: the settings are restored on
        leaving it.
    """
    return matplotlib.style.context(["default", STYLE])


def styled(fn: Callable[P, R]) -> Callable[P, R]:
    """Run the figure function ``fn`` inside :func:`figure_style`.

    Parameters
    ----------
    fn : callable
        A function that makes and saves a figure.

    Returns
    -------
    callable
        The same function, styled.
    """

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with figure_style():
            return fn(*args, **kwargs)

    return wrapper


def fixed_layout(
    fig: Figure,
    left: float,
    right: float,
    bottom: float,
    top: float,
    hspace: float = 0.0,
    wspace: float = 0.0,
) -> None:
    """Place the figure's grid of subplots with margins and gaps given in inches (what
    ``tight_layout`` finds by measuring every label, here fixed by the caller: the
    margins must hold the tick labels, axis labels, titles and legends outside the axes;
    :func:`save_png` crops the blank rest).

    With H by W axes in a figure of ``w`` by ``h`` inches, the axes' height is
    ``a_h = (h - top - bottom - (H - 1) hspace) / H`` and matplotlib's ``hspace`` is the
    gap over the mean axes height, ``hspace / a_h`` (``wspace`` likewise).

    Parameters
    ----------
    fig : Figure
        A figure whose axes lie on one grid (``subplots``).
    left, right, bottom, top : float
        Margins between the figure's edge and the grid (inches).
    hspace, wspace : float
        Gaps between rows and between columns of the grid (inches).
    """
    w, h = fig.get_size_inches()
    rows, cols = 1, 1
    for ax in fig.axes:
        spec = ax.get_subplotspec()
        if spec is not None:
            rows, cols = spec.get_topmost_subplotspec().get_gridspec().get_geometry()
            break
    ax_h = (h - top - bottom - (rows - 1) * hspace) / rows
    ax_w = (w - left - right - (cols - 1) * wspace) / cols
    fig.subplots_adjust(left=left / w, right=1.0 - right / w, bottom=bottom / h,
                        top=1.0 - top / h, hspace=hspace / ax_h, wspace=wspace / ax_w)  # fmt: skip


def ink_pixels(rgba: np.ndarray, background: np.ndarray, pad: int) -> tuple[slice, slice] | None:
    """The rows and columns of a picture around every pixel that differs from
    ``background``, ``pad`` pixels more on each side (kept inside the picture); None when
    a drawn pixel touches the picture's edge (something may lie beyond it).

    Parameters
    ----------
    rgba : ndarray, shape (H, W, 4)
        The drawn picture (uint8).
    background : ndarray, shape (4,)
        The figure's background colour (uint8).
    pad : int
        Blank pixels kept around the drawing.

    Returns
    -------
    (slice, slice) or None
        Rows (from the top) and columns; the whole picture when nothing is drawn.
    """
    # one 32-bit comparison per pixel (its four bytes at once)
    ink = rgba.view(np.uint32)[..., 0] != background.view(np.uint32)[0]
    rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
    h, w = ink.shape
    if rows.size == 0:
        return slice(0, h), slice(0, w)
    if rows[0] == 0 or cols[0] == 0 or rows[-1] == h - 1 or cols[-1] == w - 1:
        return None
    return (slice(max(rows[0] - pad, 0), min(rows[-1] + 1 + pad, h)),
            slice(max(cols[0] - pad, 0), min(cols[-1] + 1 + pad, w)))  # fmt: skip


def save_png(fig: Figure, path: str | os.PathLike, dpi: float, tight: bool = False) -> None:
    """Write ``fig`` to ``path`` as a PNG at ``dpi`` with one draw; ``tight``: cropped to
    the drawn pixels (:func:`ink_pixels`, ``savefig.pad_inches`` around them), or
    ``savefig(bbox_inches="tight")`` when the drawing reaches the canvas's edge or a
    legend leaves it. The figure is left open.

    Parameters
    ----------
    fig : Figure
        The figure.
    path : path
        The PNG file.
    dpi : float
        Dots per inch.
    tight : bool
        Crop the blank margins.
    """
    from PIL import Image, PngImagePlugin

    fig.set_dpi(dpi)
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    if tight:
        bg = np.round(to_rgba_array(fig.get_facecolor())[0] * 255).astype(np.uint8)
        pad = math.ceil(matplotlib.rcParams["savefig.pad_inches"] * dpi)
        crop = ink_pixels(rgba, bg, pad)
        if crop is None or _legend_outside(fig, canvas):  # savefig grows the canvas
            _savefig_tight(fig, path, dpi)
            return
        rgba = rgba[crop]
    pixels = rgba[..., :3] if bool((rgba[..., 3] == 255).all()) else rgba
    info = PngImagePlugin.PngInfo()
    info.add_text("Software", SOFTWARE)
    Image.fromarray(np.ascontiguousarray(pixels)).save(
        path, format="png", compress_level=COMPRESS_LEVEL, dpi=(dpi, dpi), pnginfo=info
    )


def _legend_outside(fig: Figure, canvas: FigureCanvasAgg) -> bool:
    """A legend of the figure (of its axes, also those kept with ``add_artist``, or of the
    figure) not wholly inside the canvas: one placed beyond the edge leaves no pixel
    there for :func:`ink_pixels` to see. Legends are the artists the stages place
    outside their axes; measuring only them costs little after the draw."""
    from matplotlib.legend import Legend

    legends = [*fig.legends, *(a for ax in fig.axes for a in (ax.get_legend(), *ax.artists))]
    renderer = canvas.get_renderer()
    w, h = canvas.get_width_height()
    for leg in legends:
        if isinstance(leg, Legend) and leg.get_visible():
            box = leg.get_window_extent(renderer)
            if box.x0 < 0 or box.y0 < 0 or box.x1 > w or box.y1 > h:
                return True
    return False


def _savefig_tight(fig: Figure, path: str | os.PathLike, dpi: float) -> None:
    """``savefig(bbox_inches="tight")`` as PNG at the zlib level of :func:`save_png`."""
    fig.savefig(path, dpi=dpi, format="png", bbox_inches="tight",
                pil_kwargs={"compress_level": COMPRESS_LEVEL})  # fmt: skip
