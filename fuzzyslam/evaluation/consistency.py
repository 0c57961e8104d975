"""The filter's consistency: NEES and NIS against chi-square (pure functions).

Reference: Bar-Shalom, Li, Kirubarajan, "Estimation with Applications to Tracking and
Navigation", 2001, sec. 5.4 (chi-square tests of the average over N samples).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from fuzzyslam.slam.health import chi2_quantile

Array = NDArray[np.float64]


def chi2_band(dof: int, n: int, p: float = 0.95) -> tuple[float, float]:
    """Two-sided p band of the average of n chi-square(dof) samples: chi2.ppf(.., dof n) / n
    (:func:`fuzzyslam.slam.health.chi2_quantile`, the one home of chi-square quantiles:
    scipy.special's, the same values as scipy.stats' without its import, a second of CPU).

    Parameters
    ----------
    dof : int
        Degrees of freedom of one sample.
    n : int
        Number of samples (0: NaN band).
    p : float
        The band's probability.

    Returns
    -------
    lo, hi : float
        The band of the average.
    """
    if n <= 0:
        return float("nan"), float("nan")
    a = (1.0 - p) / 2.0
    return chi2_quantile(a, dof * n) / n, chi2_quantile(1.0 - a, dof * n) / n


def nees(errors: ArrayLike, covs: ArrayLike) -> Array:
    """Normalised estimation error squared e_k^T P_k^-1 e_k per sample (NaN where P_k is singular
    or not positive definite). errors (N, d), covs (N, d, d).

    Parameters
    ----------
    errors : array_like, shape (N, d)
        Errors.
    covs : array_like, shape (N, d, d)
        Their covariances.

    Returns
    -------
    ndarray, shape (N,)
        NEES per sample.
    """
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
        """The test as a dict (field order).

        Returns
        -------
        dict
            dof, n, mean, band_lo, band_hi, in_band, frac_within_95, frac_above_100.
        """
        return asdict(self)


def consistency(values: ArrayLike, dof: int) -> Consistency:
    """Chi-square consistency test of NEES or NIS samples of ``dof`` degrees of freedom.

    The mean of n samples of chi2(dof) times n is chi2(dof n): the filter is consistent at 95 %
    when mean lies in chi2.ppf([0.025, 0.975], dof n) / n (Bar-Shalom et al. 2001, sec. 5.4).
    frac_within_95 is the share of single samples inside chi2.ppf([0.025, 0.975], dof);
    frac_above_100 the share above 100 (for 3 dof, a 10-sigma error: overconfidence).

    Parameters
    ----------
    values : array_like, shape (N,)
        NEES or NIS samples (non-finite ones dropped).
    dof : int
        Degrees of freedom of one sample.

    Returns
    -------
    Consistency
    """
    v = np.asarray(values, dtype=float).reshape(-1)
    v = v[np.isfinite(v)]
    lo, hi = chi2_band(dof, v.size)
    if v.size == 0:
        return Consistency(dof, 0, float("nan"), lo, hi, False, float("nan"))
    m = float(v.mean())
    slo, shi = chi2_quantile(0.025, dof), chi2_quantile(0.975, dof)
    frac = float(np.mean((v >= slo) & (v <= shi)))
    above = float(np.mean(v > 100.0))
    return Consistency(dof, int(v.size), m, lo, hi, bool(lo <= m <= hi), frac, above)


# An estimate grossly inconsistent with the truth (evaluate's warning). NEES samples along
# one trajectory are strongly correlated, so the band of the mean of n samples (chi2_band)
# is far too narrow to call a filter broken: a run whose mean NEES is 7 is out of it. The
# thresholds therefore hold however correlated the samples are:
# - the mean above the 99.9 % quantile of ONE chi2(dof) sample (16.3 for 3 dof): the mean
#   of identically distributed samples is never more spread than one of them (it is
#   smaller in the convex order), so a consistent filter does not get there by chance; it
#   claims errors sqrt(16.3 / 3) = 2.3 times smaller than they are, on average;
# - or more than 5 % of the samples above 100 (for 3 dof a ten-sigma error, probability
#   1.6e-21 for one sample of a consistent filter): overconfident for a long part of the log.
OVERCONFIDENT_P = 0.999
OVERCONFIDENT_SHARE_ABOVE_100 = 0.05


def overconfident_threshold(dof: int) -> float:
    """The mean NEES above which the estimate is called overconfident: the
    ``OVERCONFIDENT_P`` quantile of one chi-square(dof) sample (16.27 for 3 dof).

    Parameters
    ----------
    dof : int
        Degrees of freedom of one sample.

    Returns
    -------
    float
        The threshold.
    """
    return float(chi2_quantile(OVERCONFIDENT_P, dof))


def overconfident(c: Consistency) -> bool:
    """Whether a NEES test shows a grossly overconfident estimate: its mean above
    :func:`overconfident_threshold`, or more than ``OVERCONFIDENT_SHARE_ABOVE_100`` of its
    samples above 100 (the module's constants say why).

    Parameters
    ----------
    c : Consistency
        The test of the NEES samples (:func:`consistency`).

    Returns
    -------
    bool
        False without samples.
    """
    if c.n == 0:
        return False
    return bool(
        c.mean > overconfident_threshold(c.dof) or c.frac_above_100 > OVERCONFIDENT_SHARE_ABOVE_100
    )
