"""The odometry's turns against the filter's: a rotation scale the innovations hide.

An odometry that reports turns too short or too long (a wrong wheel base, a driver's
angular scale, a gyro's scale) misleads the filter in every turn. The landmarks and fixes
pull the heading back each time, but the correction is spread over many small updates,
each within its gate, and the map the filter builds meanwhile is bent to suit the
odometry: the innovations stay in their band (every NIS and association window of a
MRCLAM log with its turns scaled by 0.8 is in bounds) while the estimate is 10-100 times
overconfident (NEES 1050 against 5.6 for the log as recorded).

What does show it is the estimate's heading over the run: it follows the true turns
(the landmarks' bearings are measured against the map, the heading fixes against the
corridors), the dead reckoning the odometry's. Over windows of ``WINDOW_S`` seconds the
ratio of their turns,

    k = sum_i (dtheta_est,i dtheta_odo,i) / sum_i dtheta_odo,i^2

(least squares through the origin of the estimate's turn on the odometry's, one window
per sample), is the factor by which the odometry's turns must be multiplied to give the
filter's. A filter that trusts its odometry moves only part of the way towards the true
factor (1.17 for a true 1.25 on MRCLAM robot 3; 10-s windows give 1.09, the
corrections of a turn falling partly into the next window), so ``k`` bounds the error from below.
Windows whose residual is beyond three robust sigmas of the others (a relocalisation's
jump, a pose fix's correction) are left out. A run is flagged when ``k`` is off 1 by more
than ``TOLERANCE`` and by more than ``Z`` standard errors, over enough turning
(``MIN_TURN_RAD``). The idea is the one of the odometry calibration from a corrected
trajectory (Borenstein and Feng, "Measurement and correction of systematic odometry
errors in mobile robots", IEEE Trans. Robotics and Automation 12(6), 1996), here as a
check on the run's own estimate rather than on a measured square path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

WINDOW_S = 30.0  # the windows' length (s): long enough for the corrections to catch up
TOLERANCE = 0.10  # |k - 1| beyond which the odometry's turns are called off (10 %)
Z = 3.0  # ... and beyond this many standard errors
MIN_TURN_RAD = 4.0 * math.pi  # the odometry's turning, summed over the windows, needed
MIN_WINDOWS = 8  # windows with turning needed for a ratio (4 min of log)
CLIP_SIGMAS = 3.0  # windows with residuals beyond this many robust sigmas left out


@dataclass(frozen=True)
class TurnCheck:
    """The estimate's turns over the odometry's (:func:`turn_ratio`)."""

    ratio: float  # k: the odometry's turns times k give the estimate's
    sd: float  # its standard error
    windows: int  # windows used (outliers left out)
    turn_rad: float  # the odometry's turning summed over the windows used (rad)
    flagged: bool  # |k - expected| > TOLERANCE and > Z standard errors
    flagged_at: float | None  # the end of the first window from which the test holds (s)
    expected: float = 1.0  # the ratio the filter's odometry model implies (calibration)

    def as_dict(self) -> dict:
        """The summary's ``odometry_turn_check``.

        Returns
        -------
        dict
            ``ratio``, ``sd``, ``expected``, ``windows``, ``turn_deg`` and ``flagged``.
        """
        return {
            "ratio": round(self.ratio, 4),
            "expected": round(self.expected, 4),
            "sd": round(self.sd, 4),
            "windows": self.windows,
            "turn_deg": round(math.degrees(self.turn_rad), 1),
            "flagged": self.flagged,
        }


def turn_note(check: dict) -> str:
    """The flagged run's cause for the notes: which way the odometry's turns are off
    and by how much at least.

    Parameters
    ----------
    check : dict
        The summary's ``odometry_turn_check`` (:meth:`TurnCheck.as_dict`).

    Returns
    -------
    str
    """
    ratio, expected = check["ratio"], check.get("expected", 1.0)
    more = "more" if ratio > expected else "less"
    off = abs(ratio / expected - 1) * 100
    model = "the odometry" if expected == 1.0 else f"the odometry as calibrated ({expected:.3f})"
    return (
        f"odometry_turn_check: the estimate turned {off:.0f} % {more} than {model} over "
        f"{check['windows']} windows of {WINDOW_S:g} s (ratio {ratio:.3f} +- "
        f"{check['sd']:.3f}): the odometry's turns are off by at least that (a wheel base, "
        "the driver's angular scale, a gyro's scale"
        + ("; slam.calibrate: true learns it)" if expected == 1.0 else ")")
    )


def rotation_factor(names: list[str], factors: list[float]) -> float:
    """The factor by which the filter's odometry model multiplies the odometry's turns:
    1 without calibration, ``rot_scale`` for an Odometry log, and for wheel encoders
    (left + right) / 2 / base (a turn on the spot: dtheta = (s_R d_R - s_L d_L) / (s_B b)
    with d_R = -d_L; slam/calibration.py).

    Parameters
    ----------
    names, factors : list
        The calibration's parameter names and final factors (``calibration`` in the run
        summary); empty without calibration.

    Returns
    -------
    float
    """
    f = dict(zip(names, factors, strict=True))
    if "rot_scale" in f:
        return float(f["rot_scale"])
    if "base_scale" in f:
        return 0.5 * (f.get("left_scale", 1.0) + f.get("right_scale", 1.0)) / f["base_scale"]
    return 1.0


def _fit(e: np.ndarray, o: np.ndarray) -> tuple[float, float]:
    """k and its standard error for turns ``e`` = k ``o`` + noise (least squares through
    the origin; the residuals' variance with one degree of freedom spent)."""
    oo = float(np.dot(o, o))
    k = float(np.dot(e, o)) / oo
    n = len(o)
    var = float(np.sum((e - k * o) ** 2)) / max(n - 1, 1)
    return k, math.sqrt(var / oo)


def _flagged(k, sd, expected: float):
    """The test of :func:`turn_ratio` on fitted ratios (floats or arrays)."""
    off = np.abs(k / expected - 1.0)
    return (off > TOLERANCE) & (np.abs(k - expected) > Z * sd)


def turn_ratio(
    t: np.ndarray,
    yaw_est: np.ndarray,
    yaw_odo: np.ndarray,
    window_s: float = WINDOW_S,
    expected: float = 1.0,
) -> TurnCheck | None:
    """The ratio of the estimate's turns to the odometry's over windows of ``window_s``.

    The headings are sampled at the window edges (linear interpolation of the unwrapped
    headings); per window i the turns dtheta_est,i and dtheta_odo,i; k by least squares
    through the origin over the windows in which the odometry turned, after leaving out
    those whose residual dtheta_est,i - k dtheta_odo,i is beyond ``CLIP_SIGMAS`` robust
    sigmas (1.4826 times the median absolute residual) of a first fit. Its standard
    error treats the windows as independent (their noise is the filter's corrections
    within each, which do not carry over). ``flagged_at`` is the end of the first window
    from which the test, on the windows up to it, holds to the end of the run.

    Parameters
    ----------
    t : ndarray (n,)
        Times of the samples (s), increasing.
    yaw_est, yaw_odo : ndarray (n,)
        The estimate's and the dead reckoning's headings at those times (rad; wrapped or
        not).
    window_s : float
        The windows' length (s).
    expected : float
        The ratio the filter's odometry model implies (:func:`rotation_factor`): the test
        is of ``k`` against it.

    Returns
    -------
    TurnCheck or None
        None with fewer than ``MIN_WINDOWS`` windows with turning or less than
        ``MIN_TURN_RAD`` of turning.
    """
    t = np.asarray(t, dtype=float)
    if len(t) < 2 or not t[-1] - t[0] >= window_s * MIN_WINDOWS:
        return None
    edges = np.arange(t[0], t[-1] + 1e-9, window_s)
    e = np.diff(np.interp(edges, t, np.unwrap(np.asarray(yaw_est, dtype=float))))
    o = np.diff(np.interp(edges, t, np.unwrap(np.asarray(yaw_odo, dtype=float))))
    ends = edges[1:]
    turning = np.abs(o) > 1e-6
    e, o, ends = e[turning], o[turning], ends[turning]
    if len(o) < MIN_WINDOWS:
        return None
    k, _ = _fit(e, o)
    res = e - k * o
    scale = 1.4826 * float(np.median(np.abs(res)))
    keep = np.abs(res) <= CLIP_SIGMAS * scale if scale > 0 else np.ones(len(o), dtype=bool)
    e, o, ends = e[keep], o[keep], ends[keep]
    turn = float(np.sum(np.abs(o)))
    if len(o) < MIN_WINDOWS or turn < MIN_TURN_RAD:
        return None
    k, sd = _fit(e, o)
    flagged = bool(_flagged(k, sd, expected))
    at = None
    if flagged:  # the fits on the first j windows, j = 1..n, from running sums
        soo, seo, see = np.cumsum(o * o), np.cumsum(e * o), np.cumsum(e * e)
        kj = seo / soo
        dof = np.maximum(np.arange(len(o)), 1)  # j - 1
        sdj = np.sqrt(np.maximum(see - seo * kj, 0.0) / dof / soo)
        held = _flagged(kj, sdj, expected)
        held[: MIN_WINDOWS - 1] = False
        first = int(np.nonzero(~held)[0][-1]) + 1  # held from here to the end
        at = float(ends[first])
    return TurnCheck(k, sd, len(o), turn, flagged, at, expected)
