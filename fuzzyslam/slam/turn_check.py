"""The odometry's turns and distances against the filter's: scales the innovations hide.

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

The odometry's distances are checked alike (:func:`distance_ratio`): over the same
windows, the length of the estimate's displacement against the dead reckoning's,

    |de_i| = k |do_i|     (least squares through the origin)

A distance scale (a wheel radius, tyre wear, a driver's linear scale) scales every
translation of the dead reckoning, so its path is the true one's shape scaled (the turns
being right) and each window's displacement is the true one's times the scale, whatever
the turns within it; the estimate follows the true displacements as far as the
landmarks or pose fixes observe them. Lengths need no common frame (the map's and the
odometry's differ by a rotation). Heading fixes alone observe no distance: there the
estimate follows the odometry and the ratio stays near 1, whatever the scale. Measured
on MRCLAM robot 3 (whose recorded odometry overstates distances by 8 % against the
motion capture: the estimate's ratio 0.95) with its odometry's translations times 1.25,
1.1, 0.9 and 0.8: 0.88, 0.89, 1.05, 1.15 (the motion capture's 0.74, 0.84, 1.02, 1.15);
robot 2 (its odometry 1.5 % long: 1.01) times 1.25 and 0.9: 0.89, 1.10; the CARMEN pose
runs 0.96-0.99 (their simulated odometry 1 % long), the paper log 1.004.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

WINDOW_S = 30.0  # the windows' length (s): long enough for a turn's corrections
TOLERANCE = 0.10  # |k / expected - 1| beyond which the turns are called off (10 %)
Z = 3.0  # ... and beyond this many standard errors
MIN_TURN_RAD = 4.0 * math.pi  # the odometry's turning, summed over the windows, needed
MIN_WINDOWS = 8  # windows with turning needed for a ratio (4 min of log)
CLIP_SIGMAS = 3.0  # windows with residuals beyond this many robust sigmas left out
# the distance check: windows whose dead reckoning moved at least this far (m: a noise
# of 0.1 m in each end lengthens a displacement by (0.1 m)^2 / 2 / 0.5 m = 1 %) and the
# displacement needed over the windows used (the Z test judges the rest)
MIN_MOVE_M = 0.5
MIN_DIST_M = 10.0


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
    fix = ""
    if wheel_base is not None:
        fix = f"robot.wheel_base: {wheel_base / check['ratio']:.3f} (now {wheel_base:g})"
    return _scale_note(
        check, "turn", "turned", ("more", "less"), "turns",
        "a wheel base, the driver's angular scale, a gyro's scale", fix,
    )  # fmt: skip


def _scale_note(
    check: dict, name: str, verb: str, ways: tuple[str, str], what: str, causes: str, fix: str
) -> str:
    """The line of :func:`turn_note` and :func:`distance_note`: ``verb`` (turned, moved)
    ``ways`` (more or less) than the odometry (as calibrated), its ``what`` (turns,
    distances) off by at least that for ``causes``, and the ``fix`` that would make them
    agree (a config key and value; not with calibration)."""
    ratio, expected, calibrated = check["ratio"], check["expected"], check["calibrated"]
    more = ways[0] if ratio > expected else ways[1]
    off = abs(ratio / expected - 1) * 100
    model = f"the odometry as calibrated ({expected:.3f})" if calibrated else "the odometry"
    return (
        f"odometry_{name}_check: the estimate {verb} {off:.0f} % {more} than {model} over "
        f"{check['windows']} windows of {WINDOW_S:g} s (ratio {ratio:.3f} +- "
        f"{check['sd']:.3f}): the odometry's {what} are off by at least that ({causes}"
        + (")" if calibrated else "; slam.calibrate: true learns it)")
        + (f"; {fix} would make them agree, at least" if fix and not calibrated else "")
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
    edges = _window_edges(t, window_s)
    if edges is None:
        return None

    def per_window(a) -> np.ndarray:
        return np.diff(np.interp(edges, t, np.asarray(a, dtype=float)))

    e, o, ends = per_window(yaw_est), per_window(yaw_odo), edges[1:]
    d = per_window(dist) if dist is not None else None
    turning = np.abs(o) > 1e-6
    if d is not None and not np.any(np.abs(d[turning]) > 1e-3):
        d = None  # turns on the spot only: no drift per metre to tell apart
    e, o, ends = e[turning], o[turning], ends[turning]
    d = d[turning] if d is not None else None
    fit = _robust_fit(e, o, d, ends, expected, MIN_TURN_RAD)
    if fit is None:
        return None
    k, sd, c, n, turn, flagged, at = fit
    return TurnCheck(
        ratio=k, sd=sd, windows=n, turn_rad=turn, flagged=flagged, flagged_at=at,
        expected=expected, drift=c,
    )  # fmt: skip


def _window_edges(t: np.ndarray, window_s: float) -> np.ndarray | None:
    """The windows' edges from the first sample on, every ``window_s`` s (the last,
    partial window left out); None when the samples span fewer than ``MIN_WINDOWS``."""
    if len(t) < 2 or not t[-1] - t[0] >= window_s * MIN_WINDOWS:
        return None
    return np.arange(t[0], t[-1] + 1e-9, window_s)


def _robust_fit(
    e: np.ndarray,
    o: np.ndarray,
    d: np.ndarray | None,
    ends: np.ndarray,
    expected: float,
    min_amount: float,
    keep_stretches: bool = True,
) -> tuple[float, float, float, int, float, bool, float | None] | None:
    """The least-squares fit of e = k o (+ c d) over windows and its test: windows whose
    residual to a first fit is beyond ``CLIP_SIGMAS`` robust sigmas are left out, with
    ``keep_stretches`` only those whose neighbours' are not (:func:`turn_ratio`), then
    the fits on every prefix (:func:`_prefix_fits`) and the test on each
    (:func:`_flagged`).

    Returns
    -------
    tuple or None
        k, its standard error, c, the windows used, sum |o| over them, flagged and
        ``flagged_at`` (the end of the first window from which the test holds to the
        end); None with fewer than ``MIN_WINDOWS`` windows or sum |o| below
        ``min_amount``.
    """
    if len(o) < MIN_WINDOWS:
        return None
    k, _, c = (v[-1] for v in _prefix_fits(e, o, d))
    res = e - k * o - (c * d if d is not None else 0.0)
    scale = 1.4826 * float(np.median(np.abs(res)))
    out = np.abs(res) > CLIP_SIGMAS * scale if scale > 0 else np.zeros(len(o), bool)
    keep = ~(_isolated(out) if keep_stretches else out)
    e, o, ends = e[keep], o[keep], ends[keep]
    d = d[keep] if d is not None else None
    amount = float(np.sum(np.abs(o)))
    if len(o) < MIN_WINDOWS or amount < min_amount:
        return None
    kj, sdj, cj = _prefix_fits(e, o, d)
    held = _flagged(kj, sdj, expected)
    held[: MIN_WINDOWS - 1] = False
    flagged = bool(held[-1])  # the whole run's test: the last prefix
    at = None
    if flagged:
        first = int(np.nonzero(~held)[0][-1]) + 1  # held from here to the end
        at = float(ends[first])
    return float(kj[-1]), float(sdj[-1]), float(cj[-1]), len(o), amount, flagged, at


@dataclass(frozen=True)
class DistanceCheck:
    """The estimate's displacements over the odometry's (:func:`distance_ratio`)."""

    ratio: float  # k: the odometry's displacements times k give the estimate's
    sd: float  # its standard error
    windows: int  # windows used (outliers left out)
    distance_m: float  # the odometry's displacements summed over the windows used (m)
    flagged: bool  # |k / expected - 1| > TOLERANCE and |k - expected| > Z standard errors
    flagged_at: float | None  # the end of the first window from which the test holds (s)
    expected: float = 1.0  # the ratio the filter's odometry model implies (calibration)
    calibrated: bool = False  # expected is a calibration's learnt factor
    # the odometry's turns are off (the turn check's ratio beyond TOLERANCE of 1, learnt
    # by a calibration or not): they bend the dead reckoning's path, and so its
    # displacements, so the ratio is not judged (``flagged`` False; :meth:`judged`)
    confounded_by_turns: bool = False

    def as_dict(self) -> dict:
        """The summary's ``odometry_distance_check``.

        Returns
        -------
        dict
            ``ratio``, ``sd``, ``expected`` (and whether it is a calibration's),
            ``windows``, ``distance_m``, ``flagged`` and ``confounded_by_turns``.
        """
        return {
            "ratio": round(self.ratio, 4),
            "expected": round(self.expected, 4),
            "calibrated": self.calibrated,
            "sd": round(self.sd, 4),
            "windows": self.windows,
            "distance_m": round(self.distance_m, 1),
            "flagged": self.flagged,
            "confounded_by_turns": self.confounded_by_turns,
        }

    def judged(self, turns: TurnCheck | None) -> DistanceCheck:
        """This check given the run's turn check: unflagged and marked confounded when
        the odometry's turns are off by more than ``TOLERANCE`` (its ratio to the
        estimate's, whether a calibration explains it or not: a wheel base 25 % long on
        the simulated laps, the wheels right, gives a distance ratio 11 % off, the dead
        reckoning's path being bent), else itself.

        Parameters
        ----------
        turns : TurnCheck or None
            The run's :func:`turn_ratio`.

        Returns
        -------
        DistanceCheck
        """
        if turns is None or abs(turns.ratio - 1.0) <= TOLERANCE:
            return self
        return replace(self, flagged=False, flagged_at=None, confounded_by_turns=True)


def distance_ratio(
    t: np.ndarray,
    xy_est: np.ndarray,
    xy_odo: np.ndarray,
    window_s: float = WINDOW_S,
    expected: float = 1.0,
) -> DistanceCheck | None:
    """The ratio of the estimate's displacements to the odometry's over windows of
    ``window_s`` (module docstring).

    The positions are sampled at the window edges by linear interpolation; per window i
    the lengths |de_i| and |do_i| of the two displacements. Over the windows in which the
    dead reckoning moved at least ``MIN_MOVE_M``, k by least squares of |de_i| = k |do_i|
    through the origin and the run flagged as in :func:`turn_ratio` (``TOLERANCE``,
    ``Z``; at least ``MIN_WINDOWS`` windows and ``MIN_DIST_M`` of displacement), but
    every window beyond ``CLIP_SIGMAS`` robust sigmas of the first fit is left out, a
    stretch of them too: a distance scale moves every window alike, while the
    estimate's displacements have heavy tails in stretches, where relocalisations and
    map corrections move the pose over neighbouring windows (MRCLAM robot 3 with its
    distances times 1.25: 0.996 +- 0.070 keeping the stretches, 0.876 +- 0.039 without;
    the ratio the motion capture gives is 0.74). A filter that trusts its odometry
    follows its observations only part of the way, so ``k`` bounds the error from
    below. The last, partial window is not used.

    Parameters
    ----------
    t : ndarray (n,)
        Times of the samples (s), increasing.
    xy_est, xy_odo : ndarray (n, 2)
        The estimate's and the dead reckoning's positions at those times (m), each in its
        own frame.
    window_s : float
        The windows' length (s).
    expected : float
        The ratio the filter's odometry model implies (:func:`translation_factor`).

    Returns
    -------
    DistanceCheck or None
        None with too few windows that moved, or too little displacement.
    """
    t = np.asarray(t, dtype=float)
    edges = _window_edges(t, window_s)
    if edges is None:
        return None

    def lengths(xy) -> np.ndarray:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        at = np.column_stack([np.interp(edges, t, xy[:, 0]), np.interp(edges, t, xy[:, 1])])
        return np.hypot(*np.diff(at, axis=0).T)

    e, o, ends = lengths(xy_est), lengths(xy_odo), edges[1:]
    moved = o >= MIN_MOVE_M
    fit = _robust_fit(e[moved], o[moved], None, ends[moved], expected, MIN_DIST_M, False)
    if fit is None:
        return None
    k, sd, _, n, dist, flagged, at = fit
    return DistanceCheck(
        ratio=k, sd=sd, windows=n, distance_m=dist, flagged=flagged, flagged_at=at,
        expected=expected,
    )  # fmt: skip


def translation_factor(names: list[str], factors: list[float]) -> float:
    """The factor by which the filter's odometry model multiplies the odometry's
    distances: 1 without calibration, ``trans_scale`` for an Odometry log, and for wheel
    encoders (left + right) / 2 (a straight drive: d = (s_L d_L + s_R d_R) / 2 with
    d_L = d_R; slam/calibration.py).

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
    if "trans_scale" in f:
        return float(f["trans_scale"])
    if "left_scale" in f or "right_scale" in f:
        return 0.5 * (f.get("left_scale", 1.0) + f.get("right_scale", 1.0))
    return 1.0


def distance_note(check: dict, wheel_radius: float | None = None) -> str:
    """The flagged run's cause for the notes: which way the odometry's distances are off
    and by how much at least; for wheel encoders without calibration, the wheel radius
    that would make them agree (a distance is r times the wheel angle: r k; a bound, as
    the ratio is).

    Parameters
    ----------
    check : dict
        The summary's ``odometry_distance_check`` (:meth:`DistanceCheck.as_dict`).
    wheel_radius : float, optional
        ``robot.wheel_radius`` (m) when the odometry is the wheel encoders.

    Returns
    -------
    str
    """
    fix = ""
    if wheel_radius is not None:
        fix = f"robot.wheel_radius: {wheel_radius * check['ratio']:.4f} (now {wheel_radius:g})"
    return _scale_note(
        check, "distance", "moved", ("farther", "less far"), "distances",
        "a wheel radius, tyre wear, the driver's linear scale", fix,
    )  # fmt: skip
