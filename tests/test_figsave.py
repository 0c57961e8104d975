"""save_png and fixed_layout: one draw cropped to the drawn pixels (every drawn pixel kept,
the pad around them), savefig(bbox_inches="tight")'s picture when the drawing reaches the
canvas's edge, and margins placed where they were asked (inches)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pytest
from PIL import Image

from fuzzyslam.figsave import fixed_layout, ink_pixels, save_png


def _figure(legend_x: float = 1.02) -> plt.Figure:
    """A figure like Fig. 1/3: a log axis, a line, a band, a legend (at ``legend_x`` in
    axes fractions), a title and labels, in a fixed layout with generous margins."""
    fig, axes = plt.subplots(2, 1, figsize=(6, 4), sharex=True, dpi=100)
    t = np.linspace(0.0, 10.0, 400)
    axes[0].semilogy(t, np.exp(np.sin(t)) + 0.1, label="a line")
    axes[0].axhspan(0.5, 2.0, color="tab:green", alpha=0.2, label="a band")
    axes[1].plot(t, np.cos(t), ".", ms=2, label="points")
    axes[1].set_xlabel("time (s)")
    axes[0].set_ylabel("value (m)")
    axes[0].set_title("a title", y=1.0)
    fixed_layout(fig, 1.0, 0.3, 0.7, 0.5, hspace=0.3)
    axes[0].legend(loc="upper left", bbox_to_anchor=(legend_x, 1.0))
    return fig


def _pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=float)


def test_the_crop_keeps_every_drawn_pixel_and_the_pad(tmp_path) -> None:
    fig = _figure(legend_x=0.6)
    save_png(fig, tmp_path / "whole.png", 120)
    save_png(fig, tmp_path / "tight.png", 120, tight=True)
    plt.close(fig)
    whole, tight = _pixels(tmp_path / "whole.png"), _pixels(tmp_path / "tight.png")
    assert whole.shape == (480, 720, 3)
    ink = np.argwhere((whole != 255).any(axis=2))
    (r0, c0), (r1, c1) = ink.min(axis=0), ink.max(axis=0)
    pad = 12  # savefig.pad_inches (0.1 in) at 120 dpi
    # the same drawing (one draw each, the same pixels), cut pad pixels around the ink
    assert tight.shape == (r1 - r0 + 1 + 2 * pad, c1 - c0 + 1 + 2 * pad, 3)
    assert np.array_equal(tight, whole[r0 - pad : r1 + 1 + pad, c0 - pad : c1 + 1 + pad])
    assert (tight[:pad] == 255).all() and (tight[-pad:] == 255).all()
    assert (tight[:, :pad] == 255).all() and (tight[:, -pad:] == 255).all()
    assert Image.open(tmp_path / "tight.png").mode == "RGB"  # opaque: no alpha written
    # pHYs holds whole pixels per metre
    assert Image.open(tmp_path / "tight.png").info["dpi"] == pytest.approx((120, 120), abs=0.05)


@pytest.mark.parametrize("legend_x", [0.95, 1.3])  # across the edge; wholly beyond it
def test_a_drawing_past_the_edge_grows_the_picture_as_savefig(tmp_path, legend_x) -> None:
    ref, new = tmp_path / "ref.png", tmp_path / "new.png"
    fig = _figure(legend_x=legend_x)
    fig.savefig(ref, dpi=100, bbox_inches="tight", format="png")
    plt.close(fig)
    fig = _figure(legend_x=legend_x)
    save_png(fig, new, 100, tight=True)
    plt.close(fig)
    a, b = _pixels(ref), _pixels(new)
    assert a.shape[1] > 600 and a.shape == b.shape  # wider than the 6-inch figure: not cut
    assert np.abs(a - b).mean() < 0.5


def test_untight_is_the_whole_figure(tmp_path) -> None:
    fig = _figure()
    save_png(fig, tmp_path / "f.png", 110)
    plt.close(fig)
    assert Image.open(tmp_path / "f.png").size == (660, 440)


def test_ink_pixels() -> None:
    bg = np.array([255, 255, 255, 255], np.uint8)
    img = np.full((50, 80, 4), 255, np.uint8)
    assert ink_pixels(img, bg, 3) == (slice(0, 50), slice(0, 80))  # nothing drawn
    img[10:20, 30:41, 0] = 0  # one channel differs
    assert ink_pixels(img, bg, 3) == (slice(7, 23), slice(27, 44))
    assert ink_pixels(img, bg, 15) == (slice(0, 35), slice(15, 56))  # the pad kept inside
    img[49, 5, 3] = 254  # a pixel on the bottom edge: something may lie beyond
    assert ink_pixels(img, bg, 3) is None


def test_fixed_layout_places_the_margins_and_gaps_in_inches() -> None:
    fig, axes = plt.subplots(3, 2, figsize=(8, 6), dpi=100)
    fixed_layout(fig, 1.0, 0.5, 0.8, 0.4, hspace=0.3, wspace=0.6)
    boxes = np.array([[ax.get_position().bounds for ax in row] for row in axes])  # x, y, w, h
    plt.close(fig)
    x, y, w, h = (boxes[..., k] * s for k, s in enumerate((8, 6, 8, 6)))
    ax_w, ax_h = (8 - 1.0 - 0.5 - 0.6) / 2, (6 - 0.8 - 0.4 - 2 * 0.3) / 3
    assert np.allclose(w, ax_w) and np.allclose(h, ax_h)
    assert np.allclose(x[:, 0], 1.0) and np.allclose(x[:, 1], 1.0 + ax_w + 0.6)
    assert np.allclose(8 - (x[:, 1] + w[:, 1]), 0.5)
    assert np.allclose(y[-1], 0.8) and np.allclose(6 - (y[0] + h[0]), 0.4)
    assert np.allclose(y[:-1] - (y[1:] + h[1:]), 0.3)
