"""Matplotlib figures written as PNG files with one draw (the stages' figures).

``Figure.savefig(..., bbox_inches="tight")`` draws a figure twice (once with drawing
disabled, to find the tight bounding box, then for real) and PIL compresses the RGBA
picture at zlib level 6. :func:`save_png` draws once on the Agg canvas, crops the
picture to the same box (every drawn artist, ``savefig.pad_inches`` around it) when
that box lies in the figure (else it falls back to ``savefig``, which grows the canvas),
and writes RGB (the figures are opaque) at a lower zlib level: the same picture for
about a third less CPU, files a few per cent larger.
"""

from __future__ import annotations

import math
import os

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

COMPRESS_LEVEL = 3  # zlib: 6 (PIL's default) costs 1.5x the time for files 5-8 % smaller
SOFTWARE = f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/"


def tight_pixels(fig: Figure, canvas: FigureCanvasAgg) -> tuple[slice, slice] | None:
    """The rows and columns of the drawn picture inside ``savefig(bbox_inches="tight")``'s
    box (the figure's tight bounding box padded by ``savefig.pad_inches``), or None when
    the unpadded box leaves the figure (cropping would cut a drawn artist).

    Parameters
    ----------
    fig : Figure
        A figure just drawn on ``canvas``.
    canvas : FigureCanvasAgg
        Its canvas.

    Returns
    -------
    (slice, slice) or None
        Rows (from the top) and columns of the picture.
    """
    box = fig.get_tightbbox(canvas.get_renderer())  # inches, origin bottom left
    w, h = fig.get_size_inches()
    eps = 0.5 / fig.dpi  # half a pixel
    if box.x0 < -eps or box.y0 < -eps or box.x1 > w + eps or box.y1 > h + eps:
        return None
    box = box.padded(matplotlib.rcParams["savefig.pad_inches"])
    rows, cols = canvas.get_width_height()[::-1]
    d = fig.dpi
    c0, c1 = max(math.floor(box.x0 * d), 0), min(math.ceil(box.x1 * d), cols)
    r0, r1 = max(math.floor((h - box.y1) * d), 0), min(math.ceil((h - box.y0) * d), rows)
    return slice(r0, r1), slice(c0, c1)


def save_png(
    fig: Figure, path: str | os.PathLike, dpi: float, tight: bool = False, grows: bool = False
) -> None:
    """Write ``fig`` to ``path`` as a PNG at ``dpi`` with one draw; ``tight``: cropped to
    the tight bounding box, as ``savefig(bbox_inches="tight")`` (which it falls back to
    when the box leaves the figure). The figure is left open.

    ``grows`` (with ``tight``): the caller knows the box leaves the figure (a legend
    placed outside the axes): ``savefig`` at once, without the draw that would find it
    out (``savefig`` draws once without output to find the box, then once for real).

    Parameters
    ----------
    fig : Figure
        The figure.
    path : path
        The PNG file.
    dpi : float
        Dots per inch.
    tight : bool
        Crop to the drawn artists.
    grows : bool
        The drawn artists leave the figure (``tight`` only).
    """
    from PIL import Image, PngImagePlugin

    if tight and grows:
        _savefig_tight(fig, path, dpi)
        return
    fig.set_dpi(dpi)
    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba())
    if tight:
        crop = tight_pixels(fig, canvas)
        if crop is None:  # an artist outside the figure: savefig grows the canvas
            _savefig_tight(fig, path, dpi)
            return
        rgba = rgba[crop]
    pixels = rgba[..., :3] if bool((rgba[..., 3] == 255).all()) else rgba
    info = PngImagePlugin.PngInfo()
    info.add_text("Software", SOFTWARE)
    Image.fromarray(np.ascontiguousarray(pixels)).save(
        path, format="png", compress_level=COMPRESS_LEVEL, dpi=(dpi, dpi), pnginfo=info
    )


def _savefig_tight(fig: Figure, path: str | os.PathLike, dpi: float) -> None:
    """``savefig(bbox_inches="tight")`` as PNG at the zlib level of :func:`save_png`."""
    fig.savefig(path, dpi=dpi, format="png", bbox_inches="tight",
                pil_kwargs={"compress_level": COMPRESS_LEVEL})  # fmt: skip
