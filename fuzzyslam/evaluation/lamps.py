"""Estimated lamps against the true ones: a one-to-one matching (Kuhn-Munkres assignment,
``scipy.optimize.linear_sum_assignment``), duplicates, spurious and missed lamps."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from fuzzyslam.evaluation.metrics import stats

Array = NDArray[np.float64]


@dataclass
class LampMatch:
    """One-to-one assignment of estimated lamps to true lamps.

    pairs: (k, 2) indices (estimate, truth) of matched lamps; errors: (k,) distances (m);
    per_true: (n_true,) error of each true lamp's match (NaN if missed); duplicates: estimates
    left unmatched within max_dist of a matched true lamp; spurious: other unmatched estimates;
    missed: true lamps never matched.
    """

    pairs: NDArray[np.int64]
    errors: Array
    per_true: Array
    duplicates: list[int] = field(default_factory=list)
    spurious: list[int] = field(default_factory=list)
    missed: list[int] = field(default_factory=list)
    max_dist: float = 0.0

    def summary(self) -> dict[str, Any]:
        """The matching as metrics.json holds it (evaluation/results.py ``LampSummary``).

        Returns
        -------
        dict
            matched, duplicates, spurious, missed, max_dist_m, error_m, per_lamp_error_m,
            duplicate_ids, missed_ids.
        """
        s = stats(self.errors)
        return {
            "matched": int(self.errors.size),
            "duplicates": len(self.duplicates),
            "spurious": len(self.spurious),
            "missed": len(self.missed),
            "max_dist_m": self.max_dist,
            "error_m": s.to_dict(),
            "per_lamp_error_m": [None if not np.isfinite(v) else float(v) for v in self.per_true],
            "duplicate_ids": list(self.duplicates),
            "missed_ids": list(self.missed),
        }


def found_within(est_xy: ArrayLike, true_xy: ArrayLike, dist: float) -> int:
    """How many true landmarks have an estimate within ``dist`` (not one to one).

    Parameters
    ----------
    est_xy : array_like, shape (M, 2)
        Estimated landmarks.
    true_xy : array_like, shape (K, 2)
        True landmarks.
    dist : float
        The distance (m).

    Returns
    -------
    int
        The count (0 <= count <= K).
    """
    e = np.asarray(est_xy, dtype=float).reshape(-1, 2)
    t = np.asarray(true_xy, dtype=float).reshape(-1, 2)
    if e.shape[0] == 0 or t.shape[0] == 0:
        return 0
    d = np.hypot(e[:, None, 0] - t[None, :, 0], e[:, None, 1] - t[None, :, 1])
    return int((d.min(axis=0) <= dist).sum())


def match_lamps(est_xy: ArrayLike, true_xy: ArrayLike, max_dist: float) -> LampMatch:
    """Assign estimated lamps to true lamps one to one, minimising the total distance.

    Pairs farther apart than max_dist are forbidden (cost larger than any feasible total), so the
    assignment first maximises the number of feasible matches, then minimises their distance.
    An unmatched estimate within max_dist of a matched true lamp is a DUPLICATE of it (the
    paper's failure mode: an old lamp not recognised); other unmatched estimates are SPURIOUS;
    true lamps left unmatched are MISSED.

    Parameters
    ----------
    est_xy : array_like, shape (M, 2)
        Estimated lamps.
    true_xy : array_like, shape (K, 2)
        True lamps.
    max_dist : float
        Largest distance (m) of a match.

    Returns
    -------
    LampMatch
    """
    e = np.asarray(est_xy, dtype=float).reshape(-1, 2)
    t = np.asarray(true_xy, dtype=float).reshape(-1, 2)
    per_true = np.full(t.shape[0], np.nan)
    if e.shape[0] == 0 or t.shape[0] == 0:
        return LampMatch(
            np.zeros((0, 2), dtype=np.int64),
            np.zeros(0),
            per_true,
            [],
            list(range(e.shape[0])),
            list(range(t.shape[0])),
            max_dist,
        )
    d = np.hypot(e[:, None, 0] - t[None, :, 0], e[:, None, 1] - t[None, :, 1])
    feasible = d <= max_dist
    big = max_dist * (e.shape[0] + t.shape[0]) + 1.0
    rows, cols = linear_sum_assignment(np.where(feasible, d, big))
    ok = feasible[rows, cols]
    rows, cols = rows[ok], cols[ok]
    per_true[cols] = d[rows, cols]
    matched_true = np.zeros(t.shape[0], dtype=bool)
    matched_true[cols] = True
    unmatched = np.setdiff1d(np.arange(e.shape[0]), rows)
    near_matched = (feasible[unmatched] & matched_true[None, :]).any(axis=1)
    return LampMatch(
        pairs=np.column_stack([rows, cols]).astype(np.int64),
        errors=d[rows, cols],
        per_true=per_true,
        duplicates=[int(k) for k in unmatched[near_matched]],
        spurious=[int(k) for k in unmatched[~near_matched]],
        missed=[int(k) for k in np.flatnonzero(~matched_true)],
        max_dist=max_dist,
    )
