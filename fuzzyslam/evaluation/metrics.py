"""Error metrics of an estimated trajectory and map against ground truth (pure functions).

Poses are planar ``(x, y, theta)`` arrays of shape (N, 3), times in seconds. Headings are
compared on the circle (differences wrapped by :func:`fuzzyslam.se2.wrap_angle`).

References:
- APE / RPE: Sturm et al., "A benchmark for the evaluation of RGB-D SLAM systems", IROS 2012
  (ATE and RPE); Grupp, evo (github.com/MichaelGrupp/evo), whose APE aligns positions with
  Umeyama (1991) and whose RPE can take its delta in metres of travel.

The filter's consistency (NEES, NIS) is in :mod:`fuzzyslam.evaluation.consistency`, the
lamps' matching in :mod:`fuzzyslam.evaluation.lamps`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fuzzyslam.evaluation.align import umeyama
from fuzzyslam.se2 import between, interpolate_poses, wrap_angle

Array = NDArray[np.float64]


# --- summary statistics -------------------------------------------------------------------


@dataclass(frozen=True)
class Stats:
    """Summary of an error series v: mean |v|, RMSE, max |v|, std and mean (bias) of v."""

    n: int
    mean: float
    rmse: float
    max: float
    std: float
    bias: float
    median: float

    def to_dict(self) -> dict[str, Any]:
        """The statistics as a dict (field order).

        Returns
        -------
        dict of str to float
            n, mean, rmse, max, std, bias, median.
        """
        return asdict(self)

    def scaled(self, k: float) -> Stats:
        """The same statistics with the values multiplied by k > 0 (e.g. rad -> deg).

        Parameters
        ----------
        k : float
            The factor (> 0).

        Returns
        -------
        Stats
            The scaled statistics (n unchanged).
        """
        return Stats(
            self.n,
            self.mean * k,
            self.rmse * k,
            self.max * k,
            self.std * k,
            self.bias * k,
            self.median * k,
        )


def stats(values: ArrayLike) -> Stats:
    """Stats of a 1-D series (NaNs dropped); all NaN for an empty series.

    mean = (1/n) sum |v_i|, rmse = sqrt((1/n) sum v_i^2), max = max |v_i|,
    std = population std of v (as evo and numpy compute it), bias = (1/n) sum v_i,
    median = median |v_i|.

    Parameters
    ----------
    values : array_like, shape (N,)
        The error series (any shape, flattened).

    Returns
    -------
    Stats
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    v = v[np.isfinite(v)]
    if v.size == 0:
        nan = float("nan")
        return Stats(0, nan, nan, nan, nan, nan, nan)
    a = np.abs(v)
    return Stats(
        n=int(v.size),
        mean=float(a.mean()),
        rmse=float(np.sqrt(np.mean(v * v))),
        max=float(a.max()),
        std=float(v.std()),
        bias=float(v.mean()),
        median=float(np.median(a)),
    )


# --- association in time ------------------------------------------------------------------


def nearest_gap(t_ref: ArrayLike, t_query: ArrayLike) -> Array:
    """|t_query - nearest t_ref| for each query time (t_ref sorted).

    Parameters
    ----------
    t_ref : array_like, shape (N,)
        Sorted reference times.
    t_query : array_like, shape (M,)
        Query times.

    Returns
    -------
    ndarray, shape (M,)
        The gaps (s).
    """
    t_ref = np.asarray(t_ref, dtype=float)
    tq = np.asarray(t_query, dtype=float).reshape(-1)
    i = np.clip(np.searchsorted(t_ref, tq), 1, max(t_ref.size - 1, 1))
    left = np.abs(tq - t_ref[i - 1])
    right = np.abs(t_ref[np.minimum(i, t_ref.size - 1)] - tq)
    return np.minimum(left, right)


def bracket_gap(t_ref: ArrayLike, t_query: ArrayLike) -> Array:
    """The spacing t_ref[i] - t_ref[i-1] of the two reference times around each query time
    (t_ref sorted); inf for a query outside [t_ref[0], t_ref[-1]] or fewer than two times.

    Parameters
    ----------
    t_ref : array_like, shape (N,)
        Sorted reference times.
    t_query : array_like, shape (M,)
        Query times.

    Returns
    -------
    ndarray, shape (M,)
        The spacings (s).
    """
    t_ref = np.asarray(t_ref, dtype=float).reshape(-1)
    tq = np.asarray(t_query, dtype=float).reshape(-1)
    out = np.full(tq.shape, np.inf)
    if t_ref.size < 2:
        return out
    inside = (tq >= t_ref[0]) & (tq <= t_ref[-1])
    i = np.clip(np.searchsorted(t_ref, tq[inside], side="right"), 1, t_ref.size - 1)
    out[inside] = t_ref[i] - t_ref[i - 1]
    return out


@dataclass
class Associated:
    """Estimate samples paired with truth interpolated at their times.

    ``index`` holds the indices of the kept estimate samples (for rows of covariance.csv).
    """

    t: Array
    est: Array
    truth: Array
    index: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.t.size)


def covered(t_truth: ArrayLike, t_query: ArrayLike, max_dt: float, max_gap: float) -> Array:
    """Whether the truth may be interpolated at each query time (:func:`associate`'s rule):
    the two truth samples around it at most ``max_gap`` apart, or one within ``max_dt``.

    Parameters
    ----------
    t_truth : array_like, shape (K,)
        Increasing truth times.
    t_query : array_like, shape (M,)
        Query times.
    max_dt, max_gap : float
        The bounds (s).

    Returns
    -------
    ndarray of bool, shape (M,)
    """
    return (nearest_gap(t_truth, t_query) <= max_dt) | (bracket_gap(t_truth, t_query) <= max_gap)


def associate(
    t_est: ArrayLike,
    est: ArrayLike,
    t_truth: ArrayLike,
    truth: ArrayLike,
    max_dt: float,
    max_gap: float,
) -> Associated:
    """Pair each estimate with the truth interpolated at its time.

    The truth is interpolated at the estimate's stamps (:func:`fuzzyslam.se2.interpolate_poses`:
    positions linearly, headings the shorter way round the circle). An estimate sample is
    kept when its time lies inside the truth's span and either the two truth samples around
    it are at most ``max_gap`` seconds apart, or a truth sample lies within ``max_dt``
    seconds of it. So a 30 Hz estimate is compared all along a 4 Hz truth, but not in the
    middle of a gap in the truth: across a long gap a straight line would invent a truth
    the robot need not have followed (:class:`~fuzzyslam.evaluation.params.EvalParams`
    gives the bound's reason).

    Parameters
    ----------
    t_est : array_like, shape (N,)
        Estimate times.
    est : array_like, shape (N, 3)
        Estimated poses.
    t_truth : array_like, shape (K,)
        Increasing truth times.
    truth : array_like, shape (K, 3)
        True poses.
    max_dt : float
        Largest time (s) to the nearest truth sample, whatever the spacing around it.
    max_gap : float
        Largest spacing (s) of the truth samples interpolated between.

    Returns
    -------
    Associated
        The kept samples (n <= N): times, estimates, truth (n, 3) and their indices.
    """
    te = np.asarray(t_est, dtype=float).reshape(-1)
    pe = np.asarray(est, dtype=float).reshape(-1, 3)
    tt = np.asarray(t_truth, dtype=float).reshape(-1)
    pt = np.asarray(truth, dtype=float).reshape(-1, 3)
    ti = interpolate_poses(tt, pt, te)
    keep = np.isfinite(ti[:, 0]) & covered(tt, te, max_dt, max_gap)
    idx = np.flatnonzero(keep)
    return Associated(te[idx], pe[idx], ti[idx], idx)


def pose_errors(est: ArrayLike, truth: ArrayLike) -> Array:
    """Errors (N, 3) in the map frame: x_est - x_true, y_est - y_true, wrap(th_est - th_true).

    Parameters
    ----------
    est, truth : array_like, shape (N, 3)
        Paired poses.

    Returns
    -------
    ndarray, shape (N, 3)
        The errors (m, m, rad).
    """
    e = np.asarray(est, dtype=float).reshape(-1, 3) - np.asarray(truth, dtype=float).reshape(-1, 3)
    e[:, 2] = np.asarray(wrap_angle(e[:, 2])).reshape(-1)
    return e


# --- APE / RPE ----------------------------------------------------------------------------


@dataclass(frozen=True)
class ApeResult:
    """Absolute position error (norm of the position difference), raw and after alignment."""

    raw: Stats
    aligned: Stats
    aligned_scale: Stats
    alignment: dict[str, float]


def ape_translation(est_xy: ArrayLike, truth_xy: ArrayLike) -> Array:
    """||p_est,i - p_true,i|| per sample (evo's APE, translation part).

    Parameters
    ----------
    est_xy, truth_xy : array_like, shape (N, 2)
        Paired positions.

    Returns
    -------
    ndarray, shape (N,)
        The distances (m).
    """
    d = np.asarray(est_xy, dtype=float) - np.asarray(truth_xy, dtype=float)
    return np.hypot(d[:, 0], d[:, 1])


def ape(est_xy: ArrayLike, truth_xy: ArrayLike) -> ApeResult:
    """APE without alignment, with a rigid Umeyama alignment and with a similarity one.

    The alignment maps the estimated positions onto the true ones (as ``evo_ape --align``
    and ``--align --correct_scale`` do) and the error is taken after it.

    Parameters
    ----------
    est_xy, truth_xy : array_like, shape (N, 2)
        Paired positions.

    Returns
    -------
    ApeResult
        Raw, rigidly aligned and similarity-aligned statistics, and the rigid alignment.
    """
    pe = np.asarray(est_xy, dtype=float).reshape(-1, 2)
    pt = np.asarray(truth_xy, dtype=float).reshape(-1, 2)
    raw = stats(ape_translation(pe, pt))
    if pe.shape[0] < 2:
        nan = stats([])
        return ApeResult(raw, nan, nan, {})
    rigid = umeyama(pe, pt, with_scale=False)
    sim = umeyama(pe, pt, with_scale=True)
    return ApeResult(
        raw=raw,
        aligned=stats(ape_translation(rigid.apply(pe), pt)),
        aligned_scale=stats(ape_translation(sim.apply(pe), pt)),
        alignment={
            "tx": float(rigid.translation[0]),
            "ty": float(rigid.translation[1]),
            "theta_deg": float(np.degrees(rigid.angle)),
            "scale": float(sim.scale),
        },
    )


def path_length(xy: ArrayLike) -> Array:
    """Accumulated path length s_i (s_0 = 0) along positions (N, 2).

    Parameters
    ----------
    xy : array_like, shape (N, 2)
        Positions.

    Returns
    -------
    ndarray, shape (N,)
        s_i (m).
    """
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    if p.shape[0] == 0:
        return np.zeros(0)
    step = np.hypot(*np.diff(p, axis=0).T) if p.shape[0] > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(step)])


def rpe_pairs(truth_xy: ArrayLike, delta_m: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Index pairs (i, j): j is the first sample with s_j - s_i >= delta_m along the truth path.

    Parameters
    ----------
    truth_xy : array_like, shape (N, 2)
        True positions.
    delta_m : float
        The travel (m) between the two samples of a pair.

    Returns
    -------
    i, j : ndarray of int, shape (K,)
        The pairs' indices.
    """
    s = path_length(truth_xy)
    j = np.searchsorted(s, s + delta_m, side="left")
    i = np.arange(s.size)
    ok = j < s.size
    return i[ok], j[ok]


@dataclass(frozen=True)
class RpeResult:
    """Relative pose error over delta_m of true travel, per metre travelled."""

    delta_m: float
    trans_per_m: Stats
    rot_deg_per_m: Stats


def rpe_per_metre(est: ArrayLike, truth: ArrayLike, delta_m: float) -> RpeResult:
    """Relative pose error per metre of travel.

    For each pair (i, j) of :func:`rpe_pairs`, with relative motions Q_ij = Q_i^-1 Q_j (truth)
    and P_ij = P_i^-1 P_j (estimate), the error is E_ij = Q_ij^-1 P_ij (Sturm et al. 2012);
    its translation norm and |rotation| are divided by the true path length s_j - s_i.

    Parameters
    ----------
    est, truth : array_like, shape (N, 3)
        Paired poses.
    delta_m : float
        The true travel (m) of a pair.

    Returns
    -------
    RpeResult
        Translation (m/m) and rotation (deg/m) error statistics.
    """
    pe = np.asarray(est, dtype=float).reshape(-1, 3)
    pt = np.asarray(truth, dtype=float).reshape(-1, 3)
    i, j = rpe_pairs(pt[:, :2], delta_m)
    if i.size == 0:
        empty = stats([])
        return RpeResult(delta_m, empty, empty)
    s = path_length(pt[:, :2])
    dist = s[j] - s[i]
    e = between(between(pt[i], pt[j]), between(pe[i], pe[j])).reshape(-1, 3)
    return RpeResult(
        delta_m,
        stats(np.hypot(e[:, 0], e[:, 1]) / dist),
        stats(np.degrees(np.abs(e[:, 2])) / dist),
    )


# --- phases -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Phase:
    """A named time interval [t0, t1] of the experiment."""

    name: str
    t0: float
    t1: float
    runs: tuple[int, ...] = ()

    def mask(self, t: ArrayLike) -> NDArray[np.bool_]:
        """Which times lie in [t0, t1].

        Parameters
        ----------
        t : array_like, shape (N,)
            Times (s).

        Returns
        -------
        ndarray of bool, shape (N,)
        """
        t = np.asarray(t, dtype=float)
        return (t >= self.t0) & (t <= self.t1)


def phases_from_runs(
    run_intervals: list[tuple[int, float, float]],
    freeze_run: int | None,
    t_span: tuple[float, float],
) -> list[Phase]:
    """Phases: ``overall`` (t_span), ``A`` = runs 1..freeze_run, ``after`` = runs after
    freeze_run (when there are such runs), and ``run<r>`` per run.

    Parameters
    ----------
    run_intervals : list of (int, float, float)
        (run, start, end) of each run.
    freeze_run : int or None
        The last run before the map is frozen.
    t_span : (float, float)
        The compared span (overall).

    Returns
    -------
    list of Phase
    """
    out = [Phase("overall", t_span[0], t_span[1], tuple(r for r, _, _ in run_intervals))]
    if freeze_run is not None and run_intervals:
        a = [iv for iv in run_intervals if iv[0] <= freeze_run]
        b = [iv for iv in run_intervals if iv[0] > freeze_run]
        if a:
            out.append(Phase("A", a[0][1], a[-1][2], tuple(iv[0] for iv in a)))
        if b:
            out.append(Phase("after", b[0][1], b[-1][2], tuple(iv[0] for iv in b)))
    for r, t0, t1 in run_intervals:
        out.append(Phase(f"run{r}", t0, t1, (r,)))
    return out
