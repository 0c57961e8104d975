"""save_png: one draw gives savefig(bbox_inches="tight")'s picture (its box and pixels),
and falls back to savefig when an artist lies outside the figure."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pytest
from PIL import Image

from fuzzyslam.figsave import save_png


def _figure(legend_x: float = 1.02) -> plt.Figure:
    """A figure like Fig. 1/3: a log axis, a line, a band, a legend (at ``legend_x`` in
    axes fractions, placed after the layout), a title and labels."""
    fig, axes = plt.subplots(2, 1, figsize=(6, 4), sharex=True, dpi=100)
    t = np.linspace(0.0, 10.0, 400)
    axes[0].semilogy(t, np.exp(np.sin(t)) + 0.1, label="a line")
    axes[0].axhspan(0.5, 2.0, color="tab:green", alpha=0.2, label="a band")
    axes[1].plot(t, np.cos(t), ".", ms=2, label="points")
    axes[1].set_xlabel("time (s)")
    axes[0].set_ylabel("value (m)")
    axes[0].set_title("a title")
    fig.tight_layout()
    axes[0].legend(loc="upper left", bbox_to_anchor=(legend_x, 1.0))
    return fig


def _shifted_difference(a: np.ndarray, b: np.ndarray, most: int = 2) -> float:
    """The smallest mean absolute difference of two pictures over shifts of b by at most
    ``most`` pixels each way (their common part)."""
    h, w = min(a.shape[0], b.shape[0]) - 2 * most, min(a.shape[1], b.shape[1]) - 2 * most
    ref = a[most : most + h, most : most + w]
    return min(
        float(np.abs(ref - b[most + dy : most + dy + h, most + dx : most + dx + w]).mean())
        for dy in range(-most, most + 1)
        for dx in range(-most, most + 1)
    )


def _pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=float)


def _tight_pair(tmp_path, legend_x: float, dpi: int):
    """The same figure written by savefig(bbox_inches="tight") and by save_png(tight=True):
    their pixels (H, W, 3) and the new file's path."""
    ref, new = tmp_path / "ref.png", tmp_path / "new.png"
    fig = _figure(legend_x=legend_x)
    fig.savefig(ref, dpi=dpi, bbox_inches="tight", format="png")
    plt.close(fig)
    fig = _figure(legend_x=legend_x)
    save_png(fig, new, dpi, tight=True)
    plt.close(fig)
    return _pixels(ref), _pixels(new), new


def test_one_draw_gives_the_tight_savefig_picture(tmp_path) -> None:
    a, b, new = _tight_pair(tmp_path, legend_x=0.6, dpi=120)
    # the same box up to rounding to whole pixels
    assert abs(a.shape[0] - b.shape[0]) <= 2 and abs(a.shape[1] - b.shape[1]) <= 2
    # the same picture: the two agree but for anti-aliasing, once the crop's whole-pixel
    # offset is undone (a picture with anything moved, added or missing differs more)
    best = _shifted_difference(a, b)
    assert best < 1.5, best
    assert Image.open(new).mode == "RGB"  # opaque: no alpha channel written
    # pHYs holds whole pixels per metre
    assert Image.open(new).info["dpi"] == pytest.approx((120, 120), abs=0.05)


def test_an_artist_outside_the_figure_grows_the_picture_as_savefig(tmp_path) -> None:
    a, b, _ = _tight_pair(tmp_path, legend_x=1.3, dpi=100)  # the legend right of the edge
    assert a.shape[1] > 600 and a.shape == b.shape  # wider than the 6-inch figure: not cut
    assert _shifted_difference(a, b) < 0.5


def test_untight_is_the_whole_figure(tmp_path) -> None:
    fig = _figure()
    save_png(fig, tmp_path / "f.png", 110)
    plt.close(fig)
    assert Image.open(tmp_path / "f.png").size == (660, 440)
