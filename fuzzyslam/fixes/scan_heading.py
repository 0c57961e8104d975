"""Heading fixes from a laser scan's wall lines (beyond the paper; ``fixes.heading_source:
scan_lines``, docs/models.md sec. 9).

The measurement is the paper's, theta = t_ref - t_local (mod pi), with t_ref a corridor's
reference angle from the frozen FGM, but t_local comes from straight segments fitted to
the scan's end points (:mod:`fuzzyslam.fixes.scan_lines`) instead of the Hough peak of a
10 cm FLM, and the corridor is chosen so that drift of the position does not decide it:

- candidates: every unflagged reference whose region lies within ``junction_margin`` +
  3 sigma_xy of the predicted position (sigma_xy the larger axis of the filter's
  position covariance), each offering its own wall family and, with
  ``fixes.right_angles``, the family at right angles to it;
- each candidate's family is measured where it is expected, t_e = t_ref - theta_pred
  (mod pi), within a gate of max(``scan_line_gate_deg``, 3 sqrt(P_tt)) (a validation
  gate: walls of other directions, furniture and clutter outside it take no part);
- the candidate resting on the most metres of wall is the measurement; another one
  with at least half its support whose heading differs by more than
  ``ambiguity_sigmas`` sigma makes it ``ambiguous_heading``; a wrong choice is refused by
  the NIS gate (chi-square, 1 dof), never trusted;
- R = sigma_fit^2 + sigma_scan^2: sigma_fit from the segments' residuals (Birge-scaled,
  :func:`~fuzzyslam.fixes.scan_lines.family_direction`), sigma_scan =
  ``scan_line_sigma_deg`` the scatter of one scan's wall direction against truth that
  more segments of the same scan do not reduce (measured on the development logs: the
  segments of one scan agree to 0.3-0.5 deg, successive scans scatter by 1.3 deg).

The rows, summary and heading_fixes.csv are those of :class:`HeadingFixAid`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from fuzzyslam.fixes.heading import HeadingDecision, HeadingFixAid, nearest_candidate
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.references import Reference, corridors_near
from fuzzyslam.fixes.scan_lines import (
    FamilyDirection,
    Segments,
    family_direction,
    fit_segments,
    scan_end_points,
)
from fuzzyslam.se2 import wrap_angle
from fuzzyslam.slam.events import FilterView


def scan_segments(ring: Any, mounts: np.ndarray, p: FixParams) -> Segments:
    """The straight segments of one scan (robot frame), with the config's constants.

    Parameters
    ----------
    ring : Ring
        One scan read as a ring of narrow sensors (ranges (N,), max_range).
    mounts : ndarray, shape (N, 3)
        The beams' mounts (x, y, angle) in the robot frame.
    p : FixParams
        ``scan_line_points``, ``scan_line_tolerance``, ``scan_line_gap``,
        ``scan_line_min_length``.

    Returns
    -------
    Segments
        The fitted segments (``fixes/scan_lines.py``).
    """
    pts = scan_end_points(ring.ranges, ring.max_range, mounts)
    return fit_segments(
        pts, p.scan_line_points, p.scan_line_tolerance, p.scan_line_gap, p.scan_line_min_length
    )


def candidate_references(
    xy: np.ndarray, cov_xy: np.ndarray, refs: Sequence[Reference], margin: float
) -> list[Reference]:
    """The unflagged references within ``margin`` + 3 sigma_xy of ``xy`` (module docstring).

    Parameters
    ----------
    xy : ndarray, shape (2,)
        The predicted position (m).
    cov_xy : ndarray, shape (2, 2)
        Its covariance; sigma_xy is the square root of its largest eigenvalue.
    refs : sequence of Reference
        The map's corridor references.
    margin : float
        Distance (m) added to 3 sigma_xy.

    Returns
    -------
    list of Reference
    """
    sig = math.sqrt(max(float(np.linalg.eigvalsh(np.asarray(cov_xy, dtype=float))[-1]), 0.0))
    return [r for r in corridors_near(xy, refs, margin + 3.0 * sig) if not r.ambiguous]


def search_window(p_tt: float, p: FixParams) -> tuple[float, float]:
    """Where a wall family is looked for around its expected direction, and how straight
    a real wall is (module docstring).

    Parameters
    ----------
    p_tt : float
        The filter's heading variance (rad^2).
    p : FixParams
        ``scan_line_gate_deg``, ``scan_line_wall_sigma_deg``.

    Returns
    -------
    gate : float
        The window's half-width, max(``scan_line_gate_deg``, 3 sqrt(p_tt)) (rad).
    wall_sigma : float
        ``scan_line_wall_sigma_deg`` (rad).
    """
    gate = max(math.radians(p.scan_line_gate_deg), 3.0 * math.sqrt(max(p_tt, 0.0)))
    return gate, math.radians(p.scan_line_wall_sigma_deg)


def measure_heading(
    segs: Segments,
    refs: Sequence[Reference],
    predicted: float,
    p_tt: float,
    p: FixParams,
) -> tuple[float, float, Reference | None, FamilyDirection | None, str]:
    """(theta, sigma, reference, family, reason) of one scan (module docstring); theta
    and sigma are NaN, and the reason says why, when no fix is formed.

    Parameters
    ----------
    segs : Segments
        The scan's segments (robot frame).
    refs : sequence of Reference
        The candidate references (``candidate_references``).
    predicted : float
        The filter's heading (rad).
    p_tt : float
        Its variance (rad^2): the wall search gate is max(gate, 3 sqrt(p_tt)).
    p : FixParams
        The scan-line constants.

    Returns
    -------
    tuple
        theta (rad), sigma (rad), the reference used, its wall family, the reason.
    """
    nan = math.nan
    if not refs:
        return nan, nan, None, None, "no_corridor"
    gate, wall = search_window(p_tt, p)
    floor = math.radians(p.scan_line_sigma_deg)
    offsets = (0.0, math.pi / 2) if p.right_angles else (0.0,)
    found = []
    for r in refs:
        for off in offsets:
            t_ref = r.angle + off
            fam = family_direction(segs, t_ref - predicted, gate, wall, p.scan_line_min_support)
            if fam is None:
                continue
            theta, _, _ = nearest_candidate(t_ref - fam.angle, predicted, math.pi)
            found.append((fam.support, theta, math.hypot(fam.sigma, floor), r, fam))
    if not found:
        return nan, nan, None, None, "no_wall"
    found.sort(key=lambda f: -f[0])
    support, theta, sigma, ref, fam = found[0]
    for s2, th2, sg2, _, _ in found[1:]:
        if s2 < 0.5 * support:
            break
        if abs(float(wrap_angle(th2 - theta))) > p.ambiguity_sigmas * math.hypot(sigma, sg2):
            return nan, nan, ref, fam, "ambiguous_heading"
    return theta, sigma, ref, fam, "ok"


class ScanLineHeadingAid(HeadingFixAid):
    """Heading fixes from the scan's wall lines, one per scan (module docstring): the
    :class:`HeadingFixAid` plug-in with its measurement replaced (no FLM, no multi-ring
    window, no bump recovery: a laser's fix per scan needs none of them). The summary's
    ``position_sigma_max_m`` is kept as by the FLM aid; ``position_unresolved`` is not a
    finding here: the candidates are every corridor within ``junction_margin`` + 3
    sigma_xy, so the corridor is never chosen at the mean position alone."""

    def __init__(self, refs: Sequence[Reference], params: FixParams, start_time: float = 0.0):
        super().__init__(refs, params, None, None, start_time)  # type: ignore[arg-type]

    def _walls_seen(self, t: float, segs: Segments, predicted: float, p_tt: float) -> None:
        """Look at one scan's segments before its fix is measured (a subclass's check of
        the building, :class:`~fuzzyslam.fixes.live_map.LiveRightAngleHeading`; here
        nothing).

        Parameters
        ----------
        t : float
            The scan's log time (s).
        segs : Segments
            Its segments (robot frame).
        predicted : float
            The filter's heading (rad).
        p_tt : float
            Its variance (rad^2).
        """

    def on_ring(self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView) -> None:
        if not self.started(t):
            return
        p = self.params
        pose = np.asarray(ekf.pose, dtype=float)
        cov = np.asarray(ekf.pose_cov, dtype=float)
        lam = self._track_position_sigma(cov)
        if self.off_map is not None:  # the estimate against the map's free space
            self.off_map.observe(t, float(pose[0]), float(pose[1]), lam)
        predicted = float(pose[2])
        odo = float(ekf.odometry_pose[2])
        x0, y0 = float(pose[0]), float(pose[1])
        segs = scan_segments(ring, mounts, p)
        self._walls_seen(t, segs, predicted, float(cov[2, 2]))
        refs = candidate_references(pose[:2], cov[:2, :2], self.refs, p.junction_margin)
        theta, sigma, ref, fam, why = measure_heading(segs, refs, predicted, cov[2, 2], p)
        strength = fam.support if fam is not None else math.nan
        rid = ref.id if ref is not None else -1
        if why != "ok":
            self.decisions.append(
                HeadingDecision(
                    t, rid, math.nan, predicted, False, why, strength, odometry=odo, x=x0, y=y0
                )
            )
            self.pose_suspect = True
            return
        # NIS = (theta - theta_pred)^2 / (P_tt + R), R = sigma^2 (chi-square, 1 dof)
        var = float(cov[2, 2]) + sigma * sigma
        nis = float(wrap_angle(theta - predicted)) ** 2 / var
        accepted, reason = True, "ok"
        if nis > p.gate_chi2:
            accepted, reason = False, "gated"
        else:
            # h(x) = theta, H = [0 0 1 0 ...] (docs/models.md sec. 9)
            res = ekf.update_robot([theta], [[sigma * sigma]], [2], gate_chi2=p.gate_chi2)
            nis = float(res.nis)
            if not res.accepted:
                accepted, reason = False, "gated"
        self.pose_suspect = not accepted or nis > p.suspect_chi2
        self.decisions.append(
            HeadingDecision(
                t, rid, theta, predicted, accepted, reason, strength, nis, sigma, odo, False, x0, y0
            )
        )
