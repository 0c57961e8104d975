"""Estimated lamps against the true ones: a one-to-one matching (the linear assignment
problem, :func:`linear_assignment`), duplicates, spurious and missed lamps."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

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
    rows, cols = linear_assignment(np.where(feasible, d, big))
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


def linear_assignment(cost: ArrayLike) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Minimum-cost one-to-one assignment of the rows and columns of ``cost`` (min(R, C)
    pairs): the shortest augmenting path algorithm of D. F. Crouse, "On implementing 2D
    rectangular assignment algorithms", IEEE Trans. Aerospace and Electronic Systems 52(4),
    2016 (Jonker-Volgenant with dual variables), as ``scipy.optimize.linear_sum_assignment``
    implements it, step for step (the same scan order and choice among equal path costs,
    so the same pairs even where several assignments cost the same; tests compare the
    two), without importing scipy.optimize (0.5 s of CPU: ``evaluate`` needs only this).
    A tall matrix (R > C) is solved transposed. Each augmenting path is found with numpy
    over the columns left; the loops run over rows and path steps, a few per lamp.

    Parameters
    ----------
    cost : array_like, shape (R, C)
        Finite costs.

    Returns
    -------
    rows, cols : ndarray of int64, shape (min(R, C),)
        The pairs, ``rows`` ascending.
    """
    c = np.asarray(cost, dtype=np.float64)
    if c.ndim != 2 or not np.isfinite(c).all():
        raise ValueError("cost must be a finite 2-D array")
    nr, nc = c.shape
    if nr == 0 or nc == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    transpose = nc < nr
    if transpose:
        c = np.ascontiguousarray(c.T)
        nr, nc = nc, nr
    u, v = np.zeros(nr), np.zeros(nc)
    path = np.full(nc, -1, np.int64)
    col4row = np.full(nr, -1, np.int64)
    row4col = np.full(nc, -1, np.int64)
    for cur in range(nr):
        # shortest augmenting path from row ``cur`` (Crouse, Algorithm 2)
        spc = np.full(nc, np.inf)  # shortest path costs
        in_sr = np.zeros(nr, bool)
        in_sc = np.zeros(nc, bool)
        remaining = np.arange(nc - 1, -1, -1)  # reversed: a constant matrix gives the identity
        left = nc
        min_val, i, sink = 0.0, cur, -1
        while sink == -1:
            in_sr[i] = True
            rem = remaining[:left]
            r = min_val + c[i, rem] - u[i] - v[rem]
            better = r < spc[rem]
            path[rem[better]] = i
            spc[rem[better]] = r[better]
            s = spc[rem]
            lowest = s.min()
            ties = np.flatnonzero(s == lowest)
            free = ties[row4col[rem[ties]] == -1]
            # scanned in order: the first at the lowest cost, or else the last free column
            index = int(free[-1]) if free.size else int(ties[0])
            min_val = float(lowest)
            j = int(rem[index])
            if row4col[j] == -1:
                sink = j
            else:
                i = int(row4col[j])
            in_sc[j] = True
            left -= 1
            remaining[index] = remaining[left]
        # dual update, then the augmentation along the path
        u[cur] += min_val
        others = np.flatnonzero(in_sr)
        others = others[others != cur]
        u[others] += min_val - spc[col4row[others]]
        v[in_sc] -= min_val - spc[in_sc]
        j = sink
        while True:
            i = int(path[j])
            row4col[j] = i
            col4row[i], j = j, int(col4row[i])
            if i == cur:
                break
    if transpose:
        order = np.argsort(col4row)
        return col4row[order], order.astype(np.int64)
    return np.arange(nr, dtype=np.int64), col4row
