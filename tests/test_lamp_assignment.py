"""The lamp matching's one-to-one assignment: more matches first, then shorter ones."""

from __future__ import annotations

import numpy as np

from fuzzyslam.evaluation.lamps import match_lamps


def test_match_lamps_prefers_more_matches_then_shorter_ones():
    true = np.array([[0.0, 0.0], [1.0, 0.0]])
    # estimate 0 is nearest lamp 0 but alone could also take lamp 1: two matches win
    est = np.array([[0.45, 0.0], [-0.1, 0.0], [5.0, 5.0]])
    m = match_lamps(est, true, 0.6)
    assert sorted(map(tuple, m.pairs.tolist())) == [(0, 1), (1, 0)]
    assert m.spurious == [2] and m.missed == [] and m.duplicates == []
