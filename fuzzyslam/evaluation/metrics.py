"""Error metrics of an estimated trajectory and map against ground truth (pure functions).

Poses are planar ``(x, y, theta)`` arrays of shape (N, 3), times in seconds. Headings are
compared on the circle (differences wrapped by :func:`fuzzyslam.se2.wrap_angle`).

References:
- APE / RPE: Sturm et al., "A benchmark for the evaluation of RGB-D SLAM systems", IROS 2012
  (ATE and RPE); Grupp, evo (github.com/MichaelGrupp/evo), whose APE aligns positions with
  Umeyama (1991) and whose RPE can take its delta in metres of travel.
- NEES / NIS: Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking and
  Navigation", 2001, sec. 5.4 (chi-square tests of the average over N samples).
- Lamp association: Kuhn-Munkres assignment (``scipy.optimize.linear_sum_assignment``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment
from scipy.stats import chi2

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
        return asdict(self)

    def scaled(self, k: float) -> Stats:
        """The same statistics with the values multiplied by k > 0 (e.g. rad -> deg)."""
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
    """|t_query - nearest t_ref| for each query time (t_ref sorted)."""
    t_ref = np.asarray(t_ref, dtype=float)
    tq = np.asarray(t_query, dtype=float).reshape(-1)
    i = np.clip(np.searchsorted(t_ref, tq), 1, max(t_ref.size - 1, 1))
    left = np.abs(tq - t_ref[i - 1])
    right = np.abs(t_ref[np.minimum(i, t_ref.size - 1)] - tq)
    return np.minimum(left, right)


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


def associate(
    t_est: ArrayLike,
    est: ArrayLike,
    t_truth: ArrayLike,
    truth: ArrayLike,
    max_dt: float,
) -> Associated:
    """Pair each estimate with the truth interpolated at its time.

    An estimate sample is kept when its time lies inside the truth's span and a truth sample
    lies within ``max_dt`` seconds of it (so no pose is interpolated across a gap in the truth).
    """
    te = np.asarray(t_est, dtype=float).reshape(-1)
    pe = np.asarray(est, dtype=float).reshape(-1, 3)
    tt = np.asarray(t_truth, dtype=float).reshape(-1)
    pt = np.asarray(truth, dtype=float).reshape(-1, 3)
    ti = interpolate_poses(tt, pt, te)
    keep = np.isfinite(ti[:, 0]) & (nearest_gap(tt, te) <= max_dt)
    idx = np.flatnonzero(keep)
    return Associated(te[idx], pe[idx], ti[idx], idx)


def pose_errors(est: ArrayLike, truth: ArrayLike) -> Array:
    """Errors (N, 3) in the map frame: x_est - x_true, y_est - y_true, wrap(th_est - th_true)."""
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
    """||p_est,i - p_true,i|| per sample (evo's APE, translation part)."""
    d = np.asarray(est_xy, dtype=float) - np.asarray(truth_xy, dtype=float)
    return np.hypot(d[:, 0], d[:, 1])


def ape(est_xy: ArrayLike, truth_xy: ArrayLike) -> ApeResult:
    """APE without alignment, with a rigid Umeyama alignment and with a similarity one.

    The alignment maps the estimated positions onto the true ones (as ``evo_ape --align``
    and ``--align --correct_scale`` do) and the error is taken after it.
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
    """Accumulated path length s_i (s_0 = 0) along positions (N, 2)."""
    p = np.asarray(xy, dtype=float).reshape(-1, 2)
    if p.shape[0] == 0:
        return np.zeros(0)
    step = np.hypot(*np.diff(p, axis=0).T) if p.shape[0] > 1 else np.zeros(0)
    return np.concatenate([[0.0], np.cumsum(step)])


def rpe_pairs(truth_xy: ArrayLike, delta_m: float) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Index pairs (i, j): j is the first sample with s_j - s_i >= delta_m along the truth path."""
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


# --- consistency --------------------------------------------------------------------------


def chi2_band(dof: int, n: int, p: float = 0.95) -> tuple[float, float]:
    """Two-sided p band of the average of n chi-square(dof) samples: chi2.ppf(.., dof n) / n."""
    if n <= 0:
        return float("nan"), float("nan")
    a = (1.0 - p) / 2.0
    lo, hi = chi2.ppf([a, 1.0 - a], dof * n) / n
    return float(lo), float(hi)


def nees(errors: ArrayLike, covs: ArrayLike) -> Array:
    """Normalised estimation error squared e_k^T P_k^-1 e_k per sample (NaN where P_k is singular
    or not positive definite). errors (N, d), covs (N, d, d)."""
    e = np.asarray(errors, dtype=float)
    p = np.asarray(covs, dtype=float)
    out = np.full(e.shape[0], np.nan)
    if e.shape[0] == 0:
        return out
    eig = np.linalg.eigvalsh(0.5 * (p + np.swapaxes(p, -1, -2)))
    ok = np.all(eig > 0.0, axis=1) & np.all(np.isfinite(e), axis=1)
    if ok.any():
        x = np.linalg.solve(p[ok], e[ok][..., None])[..., 0]
        out[ok] = np.einsum("ij,ij->i", e[ok], x)
    return out


@dataclass(frozen=True)
class Consistency:
    """Average of chi-square statistics over n samples with its 95 % band."""

    dof: int
    n: int
    mean: float
    band_lo: float
    band_hi: float
    in_band: bool
    frac_within_95: float
    frac_above_100: float = float("nan")  # share of samples above 100: a filter in trouble

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def consistency(values: ArrayLike, dof: int) -> Consistency:
    """Chi-square consistency test of NEES or NIS samples of ``dof`` degrees of freedom.

    The mean of n samples of chi2(dof) times n is chi2(dof n): the filter is consistent at 95 %
    when mean lies in chi2.ppf([0.025, 0.975], dof n) / n (Bar-Shalom et al. 2001, sec. 5.4).
    frac_within_95 is the share of single samples inside chi2.ppf([0.025, 0.975], dof);
    frac_above_100 the share above 100 (for 3 dof, a 10-sigma error: overconfidence).
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    v = v[np.isfinite(v)]
    lo, hi = chi2_band(dof, v.size)
    if v.size == 0:
        return Consistency(dof, 0, float("nan"), lo, hi, False, float("nan"))
    m = float(v.mean())
    slo, shi = chi2.ppf([0.025, 0.975], dof)
    frac = float(np.mean((v >= slo) & (v <= shi)))
    above = float(np.mean(v > 100.0))
    return Consistency(dof, int(v.size), m, lo, hi, bool(lo <= m <= hi), frac, above)


# --- lamps --------------------------------------------------------------------------------


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
    """How many true landmarks have an estimate within ``dist`` (not one to one)."""
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


# --- phases -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Phase:
    """A named time interval [t0, t1] of the experiment."""

    name: str
    t0: float
    t1: float
    runs: tuple[int, ...] = ()

    def mask(self, t: ArrayLike) -> NDArray[np.bool_]:
        t = np.asarray(t, dtype=float)
        return (t >= self.t0) & (t <= self.t1)


def phases_from_runs(
    run_intervals: list[tuple[int, float, float]],
    freeze_run: int | None,
    t_span: tuple[float, float],
) -> list[Phase]:
    """Phases: ``overall`` (t_span), ``A`` = runs 1..freeze_run, ``after`` = runs after
    freeze_run (when there are such runs), and ``run<r>`` per run."""
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
