"""The weighted Hough accumulator of :mod:`fuzzyslam.maps.hough` (docs/models.md sec. 8).

A(rho, t) = sum_i w_i K(rho - x_i cos t - y_i sin t), K the linear (tent) kernel of one
rho bin, as a vectorised ``np.bincount``. Reference: R. O. Duda, P. E. Hart, "Use of the
Hough transformation to detect lines and curves in pictures", CACM 15(1), 1972.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np


@dataclass
class HoughPlane:
    """Accumulator ``acc`` (n_rho, n_theta) over normal angles ``thetas`` and ``rhos``
    (m, relative to ``centre``, the weighted centroid of the voting cells)."""

    acc: np.ndarray
    thetas: np.ndarray
    rhos: np.ndarray
    centre: np.ndarray


@lru_cache(maxsize=8)
def _theta_table(theta_step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The accumulator's normal angles [0, pi) in ``theta_step`` and their cos and sin
    (read-only; one table per step, not one per ring)."""
    thetas = np.arange(0.0, np.pi, theta_step)
    out = (thetas, np.cos(thetas), np.sin(thetas))
    for a in out:
        a.flags.writeable = False
    return out


def hough_accumulator(
    x: np.ndarray, y: np.ndarray, w: np.ndarray, theta_step: float, rho_step: float
) -> HoughPlane:
    """Weighted Hough accumulator A(rho, t) = sum_i w_i K(rho - x_i cos t - y_i sin t),
    K the linear (tent) kernel of one rho bin; points centred on their weighted centroid.

    Parameters
    ----------
    x, y, w : array_like, shape (N,)
        Point coordinates (m) and weights.
    theta_step, rho_step : float
        Bin sizes of the normal angle (rad) and of the distance (m).

    Returns
    -------
    HoughPlane
        The accumulator (n_rho, n_theta), its angles, distances and the centre (2,).
    """
    x, y, w = (np.asarray(a, dtype=float).ravel() for a in (x, y, w))
    thetas, cos_t, sin_t = _theta_table(float(theta_step))
    sw = w.sum()
    # the weighted centroid, as np.average computes it: sum(x w) / sum(w)
    centre = np.array([(x * w).sum() / sw, (y * w).sum() / sw]) if sw > 0 else np.zeros(2)
    xc, yc = x - centre[0], y - centre[1]
    rmax = float(np.max(np.hypot(xc, yc))) + 2 * rho_step if len(x) else rho_step
    nr = int(np.ceil(2 * rmax / rho_step)) + 1
    rhos = -rmax + np.arange(nr) * rho_step
    # r = x cos t + y sin t + rmax, u = r / rho_step, f = u - floor(u): the same
    # operations in the same order, in place (one (N, n_theta) buffer less per step)
    u = np.multiply.outer(xc, cos_t)
    u += np.multiply.outer(yc, sin_t)
    u += rmax
    u /= rho_step
    fl = np.floor(u)
    i0 = fl.astype(np.int64)
    f = u
    f -= fl  # the fractional part: rho between bins i0 and i0 + 1
    nt = len(thetas)
    cols = np.arange(nt)
    wc = w[:, None]
    # the tent's two weights w (1 - f) and w f (products commute: the same floats)
    w_lo = np.subtract(1.0, f, out=fl)
    w_lo *= wc
    f *= wc
    w_hi = f
    if len(x) and i0.min() >= 0 and i0.max() + 1 <= nr - 1:
        # no clipping (rmax leaves two bins to spare): bin i0 + 1 of a point is bin i0
        # moved one rho row, so the second sum is the first index's bincount shifted by
        # nt (the same terms in the same order: the same floats)
        i0 *= nt
        i0 += cols
        idx = i0.ravel()
        acc = np.bincount(idx, weights=w_lo.ravel(), minlength=nr * nt)
        acc[nt:] += np.bincount(idx, weights=w_hi.ravel(), minlength=nr * nt)[:-nt]
        return HoughPlane(acc.reshape(nr, nt), thetas, rhos, centre)
    # bins i0 and i0 + 1 clipped to [0, nr - 1], flattened with the angle's column
    i0c = np.minimum(np.maximum(i0, 0), nr - 1)
    i0c *= nt
    i0c += cols
    i1c = np.minimum(np.maximum(i0 + 1, 0), nr - 1)
    i1c *= nt
    i1c += cols
    acc = np.bincount(i0c.ravel(), weights=w_lo.ravel(), minlength=nr * nt)
    acc += np.bincount(i1c.ravel(), weights=w_hi.ravel(), minlength=nr * nt)
    return HoughPlane(acc.reshape(nr, nt), thetas, rhos, centre)
