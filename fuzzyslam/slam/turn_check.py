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
corridors), the dead reckoning the odometry's. Over windows of ``WINDOW_S`` seconds,
the estimate's turn de_i against the odometry's do_i and its distance dd_i,

    de_i = k do_i + c dd_i     (least squares, one row per window)

k is the factor by which the odometry's turns must be multiplied to give the filter's,
and c a heading drift per metre (unequal wheel radii, a gyro's bias), fitted apart so
that a robot turning mostly one way does not read it as a turn scale. A filter that
trusts its odometry moves only part of the way towards the true factor (1.19 for a
true 1.25 on MRCLAM robot 3), so ``k`` bounds the error from below; how far it moves
depends on the windows' length (through the origin, the same run: 1.09, 1.13, 1.17,
1.09 with 10, 20, 30, 60-s windows: too short, a turn's corrections fall into the next
window; too long, turns both ways cancel within one). Windows beyond three robust
sigmas of a first fit whose neighbours are not (a relocalisation's jump, a pose fix's
correction) are left out. A run is flagged when ``k`` is off the ratio the filter's
odometry model implies (``expected``: 1, or the self-calibration's factor) by more than
``TOLERANCE`` and by more than ``Z`` standard errors, over enough windows and turning
(``MIN_WINDOWS``, ``MIN_TURN_RAD``). The idea is the one of the odometry calibration
from a corrected trajectory (Borenstein and Feng, "Measurement and correction of
systematic odometry errors in mobile robots", IEEE Trans. Robotics and Automation
12(6), 1996: type A, the drift, and type B, the turn scale), here as a check on the
run's own estimate rather than on a measured square path; docs/models.md sec. 4.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

WINDOW_S = 30.0  # the windows' length (s): long enough for a turn's corrections
TOLERANCE = 0.10  # |k / expected - 1| beyond which the turns are called off (10 %)
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
    flagged: bool  # |k / expected - 1| > TOLERANCE and |k - expected| > Z standard errors
    flagged_at: float | None  # the end of the first window from which the test holds (s)
    expected: float = 1.0  # the ratio the filter's odometry model implies (calibration)
    drift: float = 0.0  # the estimate's heading drift against the odometry's (rad / m)
    calibrated: bool = False  # expected is a calibration's learnt factor

    def as_dict(self) -> dict:
        """The summary's ``odometry_turn_check``.

        Returns
        -------
        dict
            ``ratio``, ``sd``, ``expected`` (and whether it is a calibration's),
            ``drift_deg_per_m``, ``windows``, ``turn_deg`` and ``flagged``.
        """
        return {
            "ratio": round(self.ratio, 4),
            "expected": round(self.expected, 4),
            "calibrated": self.calibrated,
            "drift_deg_per_m": round(math.degrees(self.drift), 3),
            "sd": round(self.sd, 4),
            "windows": self.windows,
            "turn_deg": round(math.degrees(self.turn_rad), 1),
            "flagged": self.flagged,
        }


def turn_note(check: dict, wheel_base: float | None = None) -> str:
    """The flagged run's cause for the notes: which way the odometry's turns are off
    and by how much at least; for wheel encoders without calibration, the wheel base
    that would make them agree (a turn is (d_R - d_L) / b: the base b / k; a bound, as
    the ratio is).

    Parameters
    ----------
    check : dict
        The summary's ``odometry_turn_check`` (:meth:`TurnCheck.as_dict`).
    wheel_base : float, optional
        ``robot.wheel_base`` (m) when the odometry is the wheel encoders.

    Returns
    -------
    str
    """
    ratio, expected, calibrated = check["ratio"], check["expected"], check["calibrated"]
    more = "more" if ratio > expected else "less"
    off = abs(ratio / expected - 1) * 100
    model = f"the odometry as calibrated ({expected:.3f})" if calibrated else "the odometry"
    return (
        f"odometry_turn_check: the estimate turned {off:.0f} % {more} than {model} over "
        f"{check['windows']} windows of {WINDOW_S:g} s (ratio {ratio:.3f} +- "
        f"{check['sd']:.3f}): the odometry's turns are off by at least that (a wheel base, "
        "the driver's angular scale, a gyro's scale"
        + (")" if calibrated else "; slam.calibrate: true learns it)")
        + (
            f"; robot.wheel_base: {wheel_base / ratio:.3f} (now {wheel_base:g}) would make"
            " them agree, at least"
            if wheel_base is not None and not calibrated
            else ""
        )
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


def _prefix_fits(
    e: np.ndarray, o: np.ndarray, d: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fits of e = k o (+ c d) on the first j windows, j = 1..n, from running sums
    of the normal equations: k_j, its standard error and c_j (0 without ``d``).

    Through the origin (``d`` None): k = S_eo / S_oo, var k = s^2 / S_oo. With the
    distance: [S_oo S_od; S_od S_dd] [k c]^T = [S_eo S_ed]^T, var k = s^2 S_dd / det.
    s^2 is the residual sum of squares S_ee - k S_eo (- c S_ed) over j - p degrees of
    freedom (p parameters; a prefix with none left has an infinite error).

    Parameters
    ----------
    e, o : ndarray (n,)
        The estimate's and the odometry's turns per window (rad).
    d : ndarray (n,) or None
        The odometry's distance per window (m).

    Returns
    -------
    k, sd, c : ndarray (n,)
    """
    soo, seo, see = np.cumsum(o * o), np.cumsum(e * o), np.cumsum(e * e)
    j = np.arange(1, len(o) + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        if d is None:
            k, c = seo / soo, np.zeros(len(o))
            rss, dof, vk = see - k * seo, j - 1, 1.0 / soo
        else:
            sod, sdd, sed = np.cumsum(o * d), np.cumsum(d * d), np.cumsum(e * d)
            det = soo * sdd - sod * sod
            k = (seo * sdd - sed * sod) / det
            c = (sed * soo - seo * sod) / det
            rss, dof, vk = see - k * seo - c * sed, j - 2, sdd / det
        var = np.where(dof > 0, np.maximum(rss, 0.0) / np.maximum(dof, 1), np.inf)
        return k, np.sqrt(var * vk), c


def _flagged(k, sd, expected: float):
    """The test of :func:`turn_ratio` on fitted ratios (floats or arrays)."""
    off = np.abs(k / expected - 1.0)
    return (off > TOLERANCE) & (np.abs(k - expected) > Z * sd)


def _isolated(out: np.ndarray) -> np.ndarray:
    """The entries of ``out`` (bool, (n,)) whose neighbours are not: a one-off jump, not
    a stretch of the run in which the odometry behaved otherwise."""
    prev = np.concatenate([[False], out[:-1]])
    nxt = np.concatenate([out[1:], [False]])
    return out & ~prev & ~nxt


def turn_ratio(
    t: np.ndarray,
    yaw_est: np.ndarray,
    yaw_odo: np.ndarray,
    dist: np.ndarray | None = None,
    window_s: float = WINDOW_S,
    expected: float = 1.0,
) -> TurnCheck | None:
    """The ratio of the estimate's turns to the odometry's over windows of ``window_s``.

    The headings (and the distance) are sampled at the window edges by linear
    interpolation; per window i the turns de_i and do_i (and the distance dd_i). Over the
    windows in which the odometry turned, k by least squares of de_i = k do_i + c dd_i,
    the term c dd_i a heading drift per metre (unequal wheel radii, a gyro's bias:
    Borenstein and Feng's type A error, which a robot turning mostly one way would
    otherwise read as a turn scale), or through the origin without ``dist``. Windows
    whose residual is beyond ``CLIP_SIGMAS`` robust sigmas (1.4826 times the median
    absolute residual) of a first fit and whose neighbours' are not (a relocalisation's
    jump; a stretch of such windows is the odometry changing, and kept) are left out.
    The standard error treats the windows as independent (their noise is the filter's
    corrections within each). ``flagged_at`` is the end of the first window from which
    the test, on the windows kept up to it, holds to the end of the run. A whole-run
    test: a fault in the last minutes of a long log is diluted by the hours before it.
    The last, partial window is not used.

    Parameters
    ----------
    t : ndarray (n,)
        Times of the samples (s), increasing.
    yaw_est, yaw_odo : ndarray (n,)
        The estimate's and the dead reckoning's headings at those times (rad),
        continuous (not wrapped: a sampling too sparse to unwrap would alias the turns).
    dist : ndarray (n,), optional
        The dead reckoning's distance travelled at those times (m, cumulative, signed).
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

    def per_window(a) -> np.ndarray:
        return np.diff(np.interp(edges, t, np.asarray(a, dtype=float)))

    e, o, ends = per_window(yaw_est), per_window(yaw_odo), edges[1:]
    d = per_window(dist) if dist is not None else None
    turning = np.abs(o) > 1e-6
    if d is not None and not np.any(np.abs(d[turning]) > 1e-3):
        d = None  # turns on the spot only: no drift per metre to tell apart
    e, o, ends = e[turning], o[turning], ends[turning]
    d = d[turning] if d is not None else None
    if len(o) < MIN_WINDOWS:
        return None
    k, _, c = (v[-1] for v in _prefix_fits(e, o, d))
    res = e - k * o - (c * d if d is not None else 0.0)
    scale = 1.4826 * float(np.median(np.abs(res)))
    keep = ~_isolated(np.abs(res) > CLIP_SIGMAS * scale) if scale > 0 else np.ones(len(o), bool)
    e, o, ends = e[keep], o[keep], ends[keep]
    d = d[keep] if d is not None else None
    turn = float(np.sum(np.abs(o)))
    if len(o) < MIN_WINDOWS or turn < MIN_TURN_RAD:
        return None
    kj, sdj, cj = _prefix_fits(e, o, d)
    held = _flagged(kj, sdj, expected)
    held[: MIN_WINDOWS - 1] = False
    flagged = bool(held[-1])  # the whole run's test: the last prefix
    at = None
    if flagged:
        first = int(np.nonzero(~held)[0][-1]) + 1  # held from here to the end
        at = float(ends[first])
    return TurnCheck(
        ratio=float(kj[-1]),
        sd=float(sdj[-1]),
        windows=len(o),
        turn_rad=turn,
        flagged=flagged,
        flagged_at=at,
        expected=expected,
        drift=float(cj[-1]),
    )
