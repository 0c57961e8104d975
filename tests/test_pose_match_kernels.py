"""The pose matcher's image kernels against scipy.ndimage (their second implementation):
Olson's blur (a grey dilation with a non-flat element) and the 26-connected labelling
of the likelihood's high region."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from fuzzyslam.fixes.pose_match import label_26, olson_blur


@pytest.mark.parametrize("sigma", [0.6, 1.0, 2.0, 3.3])
def test_olson_blur_is_scipy_grey_dilation_to_the_bit(sigma):
    rng = np.random.default_rng(7)
    m = rng.uniform(0.0, 1.0, (37, 51)) ** 4  # mostly near-empty, some walls
    m[rng.uniform(size=m.shape) < 0.3] = 0.0  # log of the 1e-9 floor
    r = max(1, int(np.ceil(2.5 * sigma)))
    d = np.arange(-r, r + 1, dtype=np.float64)
    struct = -(d[:, None] ** 2 + d[None, :] ** 2) / (2.0 * sigma**2)
    ref = np.exp(
        ndimage.grey_dilation(
            np.log(np.maximum(m, 1e-9)), structure=struct, mode="constant", cval=-30.0
        )
    ).astype(np.float32)
    got = olson_blur(m, sigma)
    assert got.dtype == np.float32
    assert np.array_equal(got, ref)
    # the blur never lowers a cell, and a lone wall cell spreads as the Gaussian
    assert np.all(got >= m.astype(np.float32))
    one = np.zeros((21, 21))
    one[10, 10] = 1.0
    g = olson_blur(one, sigma)
    assert g[10, 10 + 1] == pytest.approx(np.exp(-1 / (2 * sigma**2)), rel=1e-6)


def _same_partition(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two labellings split the voxels into the same components (0: background)."""
    if not np.array_equal(a > 0, b > 0):
        return False
    pairs = np.unique(np.stack([a[a > 0], b[b > 0]], axis=1), axis=0)
    # a bijection between the two label sets
    return len(np.unique(pairs[:, 0])) == len(pairs) == len(np.unique(pairs[:, 1]))


@pytest.mark.parametrize("density", [0.0, 0.08, 0.2, 0.35, 0.6])
@pytest.mark.parametrize("shape", [(1, 9, 9), (5, 11, 11), (13, 21, 21), (25, 7, 31)])
def test_label_26_is_scipy_label_with_the_full_structure(shape, density):
    rng = np.random.default_rng(int(density * 100) + shape[0])
    mask = rng.uniform(size=shape) < density
    ref, nref = ndimage.label(mask, structure=np.ones((3, 3, 3), bool))
    got, n = label_26(mask)
    assert n == nref
    assert _same_partition(got, ref)
    assert set(np.unique(got)) == set(range(n + 1)) - ({0} if mask.all() else set())


def test_label_26_joins_slices_through_a_corner_only():
    mask = np.zeros((3, 5, 5), bool)
    mask[0, 1, 1] = True
    mask[1, 2, 2] = True  # diagonal neighbour of the first, one slice up
    mask[2, 4, 4] = True  # two cells away from the second: a component of its own
    labels, n = label_26(mask)
    assert n == 2
    assert labels[0, 1, 1] == labels[1, 2, 2] != labels[2, 4, 4]
    # a chain that meets only through later slices is still one component (union-find)
    chain = np.zeros((3, 1, 7), bool)
    chain[0, 0, [0, 6]] = True
    chain[1, 0, [1, 5]] = True
    chain[2, 0, 2:5] = True
    assert label_26(chain)[1] == 1
