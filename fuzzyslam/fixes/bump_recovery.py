"""Bump recovery of the heading aid (fixes/heading.py, its module docstring "Bumps"):
the streak of consistent gated single-ring fixes that calls for a recovery
(:func:`recovery_streak`), their common offset from dead reckoning
(:func:`streak_offset`), and which rings count as evidence (:func:`formed`, not at an
:func:`oblique` junction).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fuzzyslam.fixes.heading_measure import HeadingDecision
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.references import Reference
from fuzzyslam.se2 import wrap_angle, wrap_angle_period
from fuzzyslam.slam.health import chi2_quantile


def formed(d: HeadingDecision) -> bool:
    """A ring whose single-ring fix was formed and compared with the prediction.

    Parameters
    ----------
    d : HeadingDecision
        The ring's decision.

    Returns
    -------
    bool
        Reason ok, gated or recovered, with a finite measurement.
    """
    return d.reason in ("ok", "gated", "recovered") and math.isfinite(d.measured)


def oblique(refs: Sequence[Reference]) -> bool:
    """Candidate corridors whose reference angles differ by other than right angles.

    Parameters
    ----------
    refs : sequence of Reference
        The candidate corridors (at least one).

    Returns
    -------
    bool
        Some reference angle differs from the first's by more than 1 deg mod pi/2.
    """
    a0 = refs[0].angle
    return any(
        abs(float(wrap_angle_period(r.angle - a0, math.pi / 2))) > math.radians(1.0) for r in refs
    )


def streak_offset(rings: Sequence[HeadingDecision]) -> tuple[float, float, float]:
    """The rings' common offset measured - odometry (rad; weighted mean, weights 1 /
    sigma_i^2), its sigma 1 / sqrt(sum w_i), and the weighted scatter
    sum w_i (u_i - mean)^2 (chi-square with len(rings) - 1 dof when they agree).
    Offsets are taken relative to the first ring's, so no mean straddles +-pi.

    Parameters
    ----------
    rings : sequence of HeadingDecision, length k >= 1
        Formed fixes with their ``measured``, ``odometry`` and ``sigma`` (rad).

    Returns
    -------
    offset, sigma, scatter : float
        The weighted mean offset (rad, wrapped), its sigma (rad), the weighted scatter.
    """
    u = np.array([x.measured - x.odometry for x in rings], dtype=float)
    rel = np.asarray(wrap_angle(u - u[0]), dtype=float)
    w = 1.0 / np.array([x.sigma for x in rings], dtype=float) ** 2
    mean = float(np.sum(w * rel) / np.sum(w))
    scatter = float(np.sum(w * (rel - mean) ** 2))
    return float(wrap_angle(u[0] + mean)), float(1.0 / math.sqrt(float(np.sum(w)))), scatter


def recovery_streak(
    d: HeadingDecision, history: Sequence[HeadingDecision], params: FixParams
) -> list[HeadingDecision]:
    """The rings that call for a recovery at ``d`` (oldest last), or [] when none is
    due: ``d`` and the previous ``recover_after`` - 1 bump-evidence rings of
    ``history`` (all within ``recover_window_s``), all gated, whose measurements
    agree with one another (fixes/heading.py's module docstring, "Bumps").

    Evidence rings are the formed fixes (ok, gated, recovered) outside oblique
    junctions: a ring that forms no fix (no wall, ambiguous wall or heading, no
    corridor) is skipped, neither breaking nor extending the streak, and so is a ring
    at an oblique junction (its fixes can be off by a consistent 7-14 deg for several
    rings). An ok or recovered evidence ring ends the streak.

    Agreement: a bump is a step between the true and the dead-reckoning headings, so
    over a streak of about a second the offsets u_i = measured_i - odometry_i are one
    constant plus each ring's measurement noise (sigma_i, the decision's R), whereas
    the innovations measured_i - predicted_i also move with the filter (lamp updates
    drag the heading). The streak agrees when sum((u_i - u_bar)^2 / sigma_i^2), u_bar
    the weighted mean, is within chi2(k - 1) at ``recover_spread_p``.

    Parameters
    ----------
    d : HeadingDecision
        The current ring's decision (gated for a recovery to be due).
    history : sequence of HeadingDecision
        The earlier single-ring decisions, oldest first.
    params : FixParams
        ``recover_after``, ``recover_window_s``, ``recover_max_deg``, ``recover_spread_p``.

    Returns
    -------
    list of HeadingDecision
        The streak, newest first (``d`` first), or [] when no recovery is due.
    """
    k = params.recover_after
    if k <= 0 or d.oblique or d.reason != "gated" or not formed(d):
        return []
    if abs(float(wrap_angle(d.measured - d.predicted))) > math.radians(params.recover_max_deg):
        return []  # as likely another corridor's walls as a bump (recover_max_deg)
    last = [d]
    for x in reversed(history):
        if len(last) >= k or x.t < d.t - params.recover_window_s:
            break
        if not formed(x) or x.oblique:
            continue
        if x.reason != "gated":
            return []
        last.append(x)
    if len(last) < k:
        return []
    if k == 1:
        return last
    _, _, scatter = streak_offset(last)
    if not math.isfinite(scatter):
        return []
    return last if scatter <= chi2_quantile(params.recover_spread_p, k - 1) else []


def bump_position(
    streak: Sequence[HeadingDecision],
    history: Sequence[HeadingDecision],
    last_ok_xy: np.ndarray | None,
) -> np.ndarray:
    """Where the bump happened (filter frame): midway between the streak's first ring
    and the newest ring before it whose fix agreed (reason ok or recovered; else the
    position of the last accepted fix, else the first ring itself). The heading was
    right before that ring and wrong from the streak's first ring on.

    Parameters
    ----------
    streak : sequence of HeadingDecision
        The recovery's rings, newest first, with their positions ``x``, ``y``.
    history : sequence of HeadingDecision
        The earlier single-ring decisions, oldest first.
    last_ok_xy : ndarray, shape (2,), or None
        The position at the last accepted fix.

    Returns
    -------
    ndarray, shape (2,)
        The estimated position of the bump.
    """
    first = streak[-1]
    hi = np.array([first.x, first.y], dtype=float)
    lo = None
    for x in reversed(history):
        if x.t < first.t and x.reason in ("ok", "recovered") and math.isfinite(x.x):
            lo = np.array([x.x, x.y], dtype=float)
            break
    if lo is None:
        lo = hi if last_ok_xy is None else np.asarray(last_ok_xy, dtype=float)
    if not np.all(np.isfinite(hi)):
        return lo
    return 0.5 * (lo + hi)
