"""The lamp matching's assignment solver against scipy.optimize.linear_sum_assignment (its
second implementation): the same pairs, ties included, on every shape."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from fuzzyslam.evaluation.lamps import linear_assignment, match_lamps


@pytest.mark.parametrize("kind", ["uniform", "integers", "zeros", "lamps"])
def test_linear_assignment_gives_scipys_pairs(kind):
    rng = np.random.default_rng(["uniform", "integers", "zeros", "lamps"].index(kind))
    for _ in range(300):
        r, c = (int(v) for v in rng.integers(1, 20, 2))
        if kind == "uniform":
            m = rng.uniform(0, 10, (r, c))
        elif kind == "integers":  # many assignments of the same cost
            m = rng.integers(0, 4, (r, c)).astype(float)
        elif kind == "zeros":
            m = np.zeros((r, c))
        else:  # match_lamps' matrices: distances, forbidden pairs at a large cost
            e, t = rng.uniform(0, 10, (r, 2)), rng.uniform(0, 10, (c, 2))
            d = np.hypot(e[:, None, 0] - t[None, :, 0], e[:, None, 1] - t[None, :, 1])
            m = np.where(d <= 1.0, d, 1.0 * (r + c) + 1.0)
        rows, cols = linear_assignment(m)
        ref_rows, ref_cols = linear_sum_assignment(m)
        assert np.array_equal(rows, ref_rows) and np.array_equal(cols, ref_cols)
        assert rows.dtype == cols.dtype == np.int64


def test_linear_assignment_edge_cases():
    assert [len(a) for a in linear_assignment(np.zeros((0, 3)))] == [0, 0]
    rows, cols = linear_assignment([[4.0, 1.0, 3.0], [2.0, 0.0, 5.0], [3.0, 2.0, 2.0]])
    assert rows.tolist() == [0, 1, 2] and cols.tolist() == [1, 0, 2]  # cost 5, the optimum
    with pytest.raises(ValueError):
        linear_assignment([[1.0, np.inf]])


def test_match_lamps_prefers_more_matches_then_shorter_ones():
    true = np.array([[0.0, 0.0], [1.0, 0.0]])
    # estimate 0 is nearest lamp 0 but alone could also take lamp 1: two matches win
    est = np.array([[0.45, 0.0], [-0.1, 0.0], [5.0, 5.0]])
    m = match_lamps(est, true, 0.6)
    assert sorted(map(tuple, m.pairs.tolist())) == [(0, 1), (1, 0)]
    assert m.spurious == [2] and m.missed == [] and m.duplicates == []
