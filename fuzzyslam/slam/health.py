"""Numerical guards of the filter and a divergence monitor (issue 7).

- :func:`solve_spd`: S^-1 b for an innovation covariance S that should be symmetric
  positive definite, by Cholesky; a near-singular or indefinite S (a perfect
  measurement of a perfectly known state, rounding) is regularised with the smallest
  diagonal load that makes the factorisation succeed (Tikhonov; Golub & Van Loan,
  "Matrix Computations", 4th ed., sec. 4.2.8 and 6.1), never inverted blindly.
- :func:`repair_covariance`: the nearest symmetric matrix with eigenvalues >= a floor
  (Higham, "Computing a nearest symmetric positive semidefinite matrix", Linear
  Algebra Appl. 103, 1988: clip the eigenvalues of the symmetric part).
- :class:`DivergenceMonitor`: normalised innovation squared (NIS) consistency test over
  windows (Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking and
  Navigation", 2001, sec. 5.4.2): the sum of N NIS values of dof d is chi2(N d) when
  the filter is consistent; a window whose sum exceeds the ``1 - alpha`` quantile is
  out of bounds. Gated updates hide a diverged filter's large innovations (its
  detections fail the gate and become new lamps instead), so a second test watches the
  association rate: a window of detections, made while lamps are mapped, of which
  fewer than ``min_association`` were associated is out of bounds too. ``patience``
  consecutive out-of-bounds windows of either test mean divergence; so do NIS windows
  out of bounds more often than a consistent filter's rate ``alpha`` allows, consecutive
  or not (the binomial tail P(K >= k | n windows, alpha) below ``RATE_LEVEL``, by a
  margin that rounding cannot cross: a filter whose updates mislead it now and then,
  e.g. detections with x and y swapped: 7 of 28 windows out of bounds, never three in a
  row; not the first 2 windows of 2, alpha^2 = ``RATE_LEVEL`` itself, which the streak
  test's patience tolerates).
- :func:`orphan_landmarks`: a third, map-level test [ours]. An overconfident filter does
  not recognise its own landmarks when it comes back to them: their detections fail the
  gate and found new landmarks, which are in turn abandoned at the next visit. A map
  many of whose landmarks were seen in only a few frames is such a map (measured on the
  MRCLAM logs: 68-72 % of 117-169 landmarks with noise set too low, at most 5 of 14-21
  when the estimate is healthy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from fuzzyslam.slam.chi2_values import CHI2_QUANTILES, GATE_LEVELS

try:  # the LAPACK gufuncs behind numpy.linalg (private: the public calls if it moves)
    from numpy.linalg import _umath_linalg
except ImportError:  # pragma: no cover - a numpy without the module
    _umath_linalg = None


def _cholesky(s: np.ndarray) -> np.ndarray:
    """Lower Cholesky factor L of a float64 S (k, k), all NaN when S is not positive
    definite: LAPACK ``potrf`` through the gufunc ``numpy.linalg.cholesky`` calls (the same
    bits), without its Python wrapper (type and shape checks, the error-raising errstate),
    which costs 5x the factorisation of the 2x2-6x6 S of a lamp update."""
    if _umath_linalg is None:
        try:
            return np.linalg.cholesky(s)
        except np.linalg.LinAlgError:
            return np.full_like(s, np.nan)
    with np.errstate(invalid="ignore"):  # a failed factorisation: NaN, no warning
        return _umath_linalg.cholesky_lo(s, signature="d->d")


def _solve(s: np.ndarray, b: np.ndarray) -> np.ndarray:
    """S^-1 b for a float64 S (k, k) known to be well conditioned (LU, LAPACK ``gesv``):
    the gufuncs ``numpy.linalg.solve`` calls (the same bits), without its wrapper."""
    if _umath_linalg is None:
        return np.linalg.solve(s, b)
    if b.ndim == 1:
        return _umath_linalg.solve1(s, b, signature="dd->d")
    return _umath_linalg.solve(s, b, signature="dd->d")


def solve_spd(
    s: np.ndarray, b: np.ndarray, rel_eps: float = 1e-12, abs_eps: float = 1e-15
) -> tuple[np.ndarray, bool]:
    """x = S^-1 b for symmetric S; returns (x, regularised).

    Cholesky S = L L^T. S counts as near-singular when the factorisation fails or
    min(diag L)^2 <= rel_eps max(diag L)^2 (a condition number beyond ~1/rel_eps); it is
    then solved as S + e I with e = max(rel_eps trace(S)/k, abs_eps) (abs_eps in the
    units of S: 1e-15 m^2 or rad^2), e grown tenfold until the factorisation succeeds.

    Parameters
    ----------
    s : ndarray, shape (k, k)
        Symmetric S.
    b : ndarray, shape (k,) or (k, n)
        Right-hand side.
    rel_eps : float
        Relative singularity threshold.
    abs_eps : float
        Smallest regularisation (units of S).

    Returns
    -------
    x : ndarray, shape of ``b``
    regularised : bool
    """
    s = 0.5 * (s + s.T)
    if not (np.isfinite(s).all() and np.isfinite(b).all()):
        raise np.linalg.LinAlgError("innovation covariance or innovation is not finite")
    # diag(L)^2: all positive, or all NaN when S is not positive definite (then the test
    # fails); on floats: k values
    d = (_cholesky(s).diagonal() ** 2).tolist()
    if min(d) > rel_eps * max(d):
        return _solve(s, b), False
    k = s.shape[0]
    eps = max(rel_eps * float(np.abs(np.trace(s))) / k, abs_eps)
    for _ in range(40):
        reg = s + eps * np.eye(k)
        if not np.isnan(_cholesky(reg)[0, 0]):  # the test of positive definiteness
            return _solve(reg, b), True
        eps *= 10.0
    raise np.linalg.LinAlgError("innovation covariance cannot be regularised")


@lru_cache(maxsize=256)
def chi2_quantile(p: float, dof: int) -> float:
    """chi2.ppf(p, dof) = 2 P^-1(dof/2, p) (P the regularised lower incomplete gamma);
    scipy.special, not scipy.stats, whose import costs a second and 40 MB; at the points
    of ``slam/chi2_values.py`` its value without importing scipy."""
    v = CHI2_QUANTILES.get((p, dof))
    if v is not None:
        return v
    from scipy.special import gammaincinv

    return float(2.0 * gammaincinv(dof / 2.0, p))


@lru_cache(maxsize=64)
def gate_level(gate_chi2: float) -> float:
    """The confidence level of a 2-dof chi-square gate: chi2.cdf(gate, 2) = P(1, gate/2)
    (scipy.special; at the points of ``slam/chi2_values.py`` without importing it)."""
    v = GATE_LEVELS.get(gate_chi2)
    if v is not None:
        return v
    from scipy.special import gammainc

    return float(gammainc(1.0, gate_chi2 / 2.0))


def is_spd(p: np.ndarray) -> bool:
    """True if P is finite, exactly symmetric and its Cholesky factorisation succeeds.

    Parameters
    ----------
    p : ndarray, shape (n, n)
        A covariance.

    Returns
    -------
    bool
    """
    if not np.all(np.isfinite(p)) or not np.array_equal(p, p.T):
        return False
    try:
        np.linalg.cholesky(p)
    except np.linalg.LinAlgError:
        return False
    return True


def repair_covariance(p: np.ndarray, floor: float = 1e-12) -> tuple[np.ndarray, bool]:
    """(P', repaired): P itself if symmetric positive definite, else its nearest symmetric
    matrix with eigenvalues >= ``floor`` (relative to the largest): V max(L, f) V^T.

    Parameters
    ----------
    p : ndarray, shape (n, n)
        A covariance.
    floor : float
        Smallest eigenvalue relative to the largest.

    Returns
    -------
    p : ndarray, shape (n, n)
    repaired : bool
    """
    if is_spd(p):
        return p, False
    sym = 0.5 * (p + p.T)
    sym = np.where(np.isfinite(sym), sym, 0.0)
    w, v = np.linalg.eigh(sym)
    f = floor * max(float(np.abs(w).max()), 1e-300)
    out = (v * np.maximum(w, f)) @ v.T
    return 0.5 * (out + out.T), True


# binomial tail below which out-of-bounds NIS windows are too many. Not at it: 2 of the
# first 2 windows out is alpha^2 = 1e-6 exactly, and two windows out in a row is what the
# streak test's patience of 3 tolerates anywhere in a run; the rate test is no shortcut
# around it at the start (a pose-fix run on a short log, which closes 1-2 windows, is
# judged by its matches instead: fixes/pose_aid.py, pose_matches_refused)
RATE_LEVEL = 1e-6
# the reasons DivergenceMonitor's windows give (its streak tests, "nis" and "association",
# and the NIS rate test): where they were found, its out-of-bounds spans say
WINDOW_REASONS = frozenset({"nis", "nis_rate", "association"})
RATE_RTOL = 1e-9  # relative margin of that comparison: the log-space sum gives alpha^2
# as 1.0000000000000004e-06 at alpha = 1e-3, as 9.999999999999987e-07 at 1e-3 (1 - 1e-15)


def rate_exceeded(k: int, n: int, alpha: float) -> bool:
    """Whether k of n windows out of bounds is a rate a consistent filter (``alpha`` per
    window) gives with probability below ``RATE_LEVEL``: P(K >= k) < RATE_LEVEL, by more
    than the relative margin ``RATE_RTOL``, so that rounding in :func:`binomial_tail`
    does not decide a tail equal to the level (2 of 2 at alpha = 1e-3: not divergence,
    whichever way its last bit falls).

    Parameters
    ----------
    k, n : int
        Windows out of bounds, windows closed.
    alpha : float
        A consistent filter's probability of a window out of bounds.

    Returns
    -------
    bool
    """
    return binomial_tail(k, n, alpha) < RATE_LEVEL * (1.0 - RATE_RTOL)


def binomial_tail(k: int, n: int, p: float) -> float:
    """P(K >= k) for K ~ Binomial(n, p), summed term by term in log space (lgamma: no
    overflow for any n), from k up until the terms, decreasing past the mean, no longer
    change the sum (no scipy in a run's start-up).

    Parameters
    ----------
    k, n : int
        Successes and trials.
    p : float
        The success probability.

    Returns
    -------
    float
    """
    if k <= 0:
        return 1.0
    if k > n:
        return 0.0
    lp, lq, ln = math.log(p), math.log1p(-p), math.lgamma(n + 1)
    terms: list[float] = []
    for i in range(k, n + 1):
        term = math.exp(ln - math.lgamma(i + 1) - math.lgamma(n - i + 1) + i * lp + (n - i) * lq)
        terms.append(term)
        if i > n * p and term <= 1e-17 * terms[0]:
            break  # past the mean the terms fall geometrically: the rest is below rounding
    return min(math.fsum(terms), 1.0)


@dataclass
class _Windows:
    """Consecutive windows of one test: counts, the current streak, the spans out of bounds."""

    windows: int = 0
    out_of_bounds: int = 0
    streak: int = 0
    spans: list[tuple[float, float]] = field(default_factory=list)

    def close(self, t0: float, t1: float, bad: bool) -> int:
        self.windows += 1
        if not bad:
            self.streak = 0
            return 0
        self.out_of_bounds += 1
        self.streak += 1
        if self.streak == 1:
            self.spans.append((t0, t1))
        else:
            self.spans[-1] = (self.spans[-1][0], t1)
        return self.streak


@dataclass
class DivergenceMonitor:
    """Windowed NIS and association-rate tests (module docstring).

    ``observe(t, nis, dof)`` per update; ``observe_frame(t, detections, associated)``
    per camera frame taken while lamps are mapped. ``diverged`` once ``patience``
    consecutive windows of one test are out of bounds.
    """

    window: int = 50
    alpha: float = 1e-3
    patience: int = 3
    assoc_window: int = 100
    min_association: float = 0.5
    diverged_at: float | None = None
    worst_ratio: float = 0.0
    nis: _Windows = field(default_factory=_Windows)
    assoc: _Windows = field(default_factory=_Windows)
    _sum: float = 0.0
    _dof: int = 0
    _n: int = 0
    _t0: float = 0.0
    _det: int = 0
    _ok: int = 0
    _ta: float = 0.0
    births: int = 0
    births_untrusted: int = 0
    reasons: list[str] = field(default_factory=list)  # the tests that found divergence

    def observe(self, t: float, nis: float, dof: int) -> None:
        """One update's NIS (``dof`` its degrees of freedom).

        Parameters
        ----------
        t : float
            The update's time (s).
        nis : float
            Its NIS (non-finite: counted as 1e6).
        dof : int
            Its degrees of freedom.
        """
        if self._n == 0:
            self._t0 = t
        self._sum += nis if math.isfinite(nis) else 1e6
        self._dof += dof
        self._n += 1
        if self._n >= self.window:
            bound = chi2_quantile(1.0 - self.alpha, self._dof)
            ratio = self._sum / bound
            self.worst_ratio = max(self.worst_ratio, ratio)
            self._streak(t, self.nis.close(self._t0, t, ratio > 1.0), "nis")
            self._sum, self._dof, self._n = 0.0, 0, 0
            w = self.nis
            if (
                ratio > 1.0
                and "nis_rate" not in self.reasons
                and rate_exceeded(w.out_of_bounds, w.windows, self.alpha)
            ):
                self.diverged_at = t if self.diverged_at is None else self.diverged_at
                self.reasons.append("nis_rate")

    def observe_frame(self, t: float, detections: int, associated: int) -> None:
        """One frame's detections and how many were associated with mapped lamps.

        Parameters
        ----------
        t : float
            The frame's time (s).
        detections : int
            Lamps detected.
        associated : int
            Of them, associated with mapped lamps.
        """
        if detections <= 0:
            return
        if self._det == 0:
            self._ta = t
        self._det += detections
        self._ok += associated
        if self._det >= self.assoc_window:
            bad = self._ok < self.min_association * self._det
            self._streak(t, self.assoc.close(self._ta, t, bad), "association")
            self._det, self._ok = 0, 0

    @property
    def untrusted(self) -> bool:
        """The latest closed window of either test was out of bounds."""
        return self.nis.streak > 0 or self.assoc.streak > 0

    def observe_birth(self, t: float, pose_cov: np.ndarray) -> None:
        """A landmark initialised at ``t`` (from a pose of covariance ``pose_cov``); counted
        as untrusted when the latest window of either test is out of bounds: its position
        inherits an error the filter does not admit (a future duplicate).

        Parameters
        ----------
        t : float
            The birth time (s).
        pose_cov : ndarray, shape (3, 3)
            The robot's covariance then.
        """
        self.births += 1
        if self.untrusted:
            self.births_untrusted += 1

    def _streak(self, t: float, streak: int, test: str) -> None:
        if streak >= self.patience:
            if self.diverged_at is None:
                self.diverged_at = t
            if test not in self.reasons:
                self.reasons.append(test)

    @property
    def diverged(self) -> bool:
        return self.diverged_at is not None

    @property
    def windows(self) -> int:
        return self.nis.windows

    @property
    def out_of_bounds(self) -> int:
        return self.nis.out_of_bounds

    def summary(self) -> dict:
        """The summary's ``filter_health`` (without the numerical guards).

        Returns
        -------
        dict
            Window counts, births, ``diverged``, ``reasons``, ``diverged_at``, spans.
        """
        spans = sorted(self.nis.spans + self.assoc.spans)
        return {
            "nis_windows": self.nis.windows,
            "nis_windows_out_of_bounds": self.nis.out_of_bounds,
            "nis_worst_window_ratio": round(self.worst_ratio, 3),
            "association_windows": self.assoc.windows,
            "association_windows_out_of_bounds": self.assoc.out_of_bounds,
            "landmark_births": self.births,
            "landmark_births_untrusted": self.births_untrusted,
            "diverged": self.diverged,
            "reasons": list(self.reasons),
            "diverged_at": self.diverged_at,
            "out_of_bounds_spans": [[round(a, 3), round(b, 3)] for a, b in spans[:5]],
        }


def orphan_landmarks(
    first_seen: np.ndarray,
    observations: np.ndarray,
    min_observations: int = 20,
    max_fraction: float = 0.3,
    min_count: int = 5,
) -> tuple[int, float | None]:
    """Landmarks associated in fewer than ``min_observations`` frames (orphans), and the
    time (a birth time) from which the map holds more than ``min_count`` of them and more
    than ``max_fraction`` of its landmarks (None: never).

    Parameters
    ----------
    first_seen : (n,) birth times of the landmarks (s).
    observations : (n,) frames in which each landmark was associated.

    Returns
    -------
    count : int
        Orphans.
    at : float or None
        The time the map turned untrustworthy.
    """
    order = np.argsort(first_seen, kind="stable")
    orphan = np.asarray(observations)[order] < min_observations
    count = np.cumsum(orphan)
    total = np.arange(1, len(order) + 1)
    bad = (count > min_count) & (count > max_fraction * total)
    at = float(np.asarray(first_seen)[order][np.argmax(bad)]) if bad.any() else None
    return int(orphan.sum()), at
