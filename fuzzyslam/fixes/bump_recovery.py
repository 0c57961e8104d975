"""Bump recovery of the heading aid (fixes/heading.py, its module docstring "Bumps"):
the streak of consistent gated single-ring fixes that calls for a recovery
(:func:`recovery_streak`), the sequential test that calls for one as soon as the rings'
evidence suffices (:func:`sequential_streak`, :func:`jump_log_odds`), their common
offset from dead reckoning (:func:`streak_offset`), and which rings count as evidence
(:func:`formed`, not at an :func:`unsure_junction`; :func:`ring_evidence`).

The sequential test [ours, after Wald, "Sequential tests of statistical hypotheses",
Ann. Math. Stat. 16(2), 1945, with a mixture over the unknown jump]. A bump turns the
true heading by delta in one step; the rings since then measure it, each with its own
noise and its own rate of gross errors. Ring i (candidate heading z_i, mapped to the
current ring by the dead reckoning, which does not see the bump: v_i = z_i - o_i + o_k
- theta_pred) has, with s_i its standard deviation and eps_i its gross-error rate,

    H1 (jump delta):  p1(v_i | delta) = (1 - eps_i) N(v_i; delta, s_i^2) + eps_i / T
    H0 (no jump):     p0(v_i)         = (1 - eps_i) N(v_i; 0, s_i^2 + P_tt) + eps_i / T

T the comb's period (a gross error is any wall direction). delta is unknown and
uniform over one period, so the evidence is the Bayes factor

    B = (1/T) integral prod_i p1(v_i | delta) d delta  /  prod_i p0(v_i)

and a recovery is due when B >= 1 / alpha (Wald's bound A = (1 - beta) / alpha, beta
-> 0: the rings that follow keep testing). The outlier term caps what one ring can
say: a ring far from the prediction gives at most about 1 / eps_i, whatever its
innovation, so one ring could decide alone only where its gross errors were rarer than
alpha; with the defaults none does (1 / eps_i <= 2300 < 1 / alpha = 5000,
``fixes.recover_alpha``): a second agreeing ring decides, and so do weaker rings that
lean the same way (loose fits, ambiguous_wall rings in one corridor, whose dominant
wall is still a measurement with its fit's sigma), each adding what it carries.

The product over rings assumes independent gross errors. In corridors none of the
tight or ambiguous rings had one (paper log, seeds 0-2, phases C and D away from the
bumps: 0 of 7045 and 0 of 774). At junctions they come in runs that agree (the other
corridor's wall, several rings long): 6.0 % of the junction fixes are gross, 13.5 % of
those after a gross one, and 13 % of such pairs agree within 3 deg (3 % if independent),
so two agreeing junction rings are about 9 times as common as the model says, and they
did recover a correct heading (seed 1 of paper_bumps, 0.6 s before a bump). Junction
rings are left to the streak rule (:func:`recovery_streak`, ``recover_after`` agreeing
rings), which was made for them.
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


def one_direction(refs: Sequence[Reference]) -> bool:
    """Candidate corridors that all run one way: reference angles within 1 deg mod pi.

    Parameters
    ----------
    refs : sequence of Reference
        The candidate corridors (at least one).

    Returns
    -------
    bool
        Every reference angle within 1 deg of the first's, mod pi.
    """
    a0 = refs[0].angle
    return all(
        abs(float(wrap_angle_period(r.angle - a0, math.pi))) <= math.radians(1.0) for r in refs
    )


def unsure_junction(refs: Sequence[Reference]) -> bool:
    """A junction (outside every corridor region, or in regions of different angles)
    whose rings are no bump evidence: its candidate corridors are :func:`oblique`, or
    they all run one way (:func:`one_direction`).

    Oblique: the FLM's wall was measured 7-14 deg off for 3-6 rings in a row at the
    corners of the 70-degree corridor (paper_bumps.yaml, 4 of 5 seeds), which
    consistency cannot tell from a bump. One direction: outside every region, with the
    regions near it all parallel, the robot is at no junction the map knows of; it is
    beyond a region's trimmed end, or in a corridor the map has no reference for (a
    one-lap map's path-based segments can miss one, ``maps/references.py``), whose
    walls, consistently seen for many rings, make a gated streak as long as the robot
    stays there: as likely that corridor as a bump. Measured on the quick world with
    every lamp off in run 2 (docs/models.md sec. 9): seeds 9 and 12, in the start
    corridor's half the map has no reference for, 1.7 m from the left corridor's
    region, three junction rings 89-90 deg off recovered a correct heading (the
    position variance inflated to 12-16 m^2, the pose lost); seed 10, in the left
    corridor (no reference), 81 deg off against the top corridor's.

    Parameters
    ----------
    refs : sequence of Reference
        The candidate corridors (at least one).

    Returns
    -------
    bool
    """
    return oblique(refs) or one_direction(refs)


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


def ring_evidence(x: HeadingDecision, params: FixParams) -> tuple[float, float, float] | None:
    """A ring's heading candidate for the jump test, its standard deviation and its
    gross-error rate (module docstring), or None when it carries none.

    Formed corridor fixes: the measurement, s = sigma_heading_deg and
    ``recover_outlier_fit`` when the wall fit's sigma is within it, else
    s = max(fit, sigma_heading_deg) and ``recover_outlier_loose`` (also without a fit:
    the Hough's peak alone). An ambiguous_wall ring in one corridor with a fit: its
    dominant wall's candidate, s = max(fit, sigma_heading_deg),
    ``recover_outlier_ambiguous``. Junction rings and any other ring: None.

    Parameters
    ----------
    x : HeadingDecision
        The ring's single-ring decision (``measured``, ``candidate``, ``fit_sigma``).
    params : FixParams
        The sigmas and the ``recover_outlier_*`` rates.

    Returns
    -------
    (float, float, float) or None
        Candidate heading (rad), its sigma (rad), its gross-error rate.
    """
    sh = math.radians(params.sigma_heading_deg)
    known = math.isfinite(x.fit_sigma)
    fit = x.fit_sigma if known else 0.0
    if x.junction:
        return None  # gross errors in agreeing runs (module docstring): the streak rule's
    if formed(x):
        if known and fit <= sh:
            return x.measured, sh, params.recover_outlier_fit
        return x.measured, max(sh, fit), params.recover_outlier_loose
    if x.reason == "ambiguous_wall" and math.isfinite(x.candidate) and known:
        return x.candidate, max(sh, fit), params.recover_outlier_ambiguous
    return None


def jump_log_odds(
    v: np.ndarray, s: np.ndarray, eps: np.ndarray, p_tt: float, period: float
) -> float:
    """log B, the Bayes factor of "the heading jumped by an unknown delta" against "it did
    not" (module docstring), delta uniform over one period, integrated on a grid of
    steps s_min / 8.

    Parameters
    ----------
    v : ndarray, shape (n,)
        The rings' innovations against the current prediction (rad).
    s : ndarray, shape (n,)
        Their standard deviations (rad).
    eps : ndarray, shape (n,)
        Their gross-error rates.
    p_tt : float
        The filter's heading variance (rad^2).
    period : float
        The comb's period T (rad).

    Returns
    -------
    float
        log B.
    """
    v, s, eps = (np.asarray(a, dtype=float).reshape(-1, 1) for a in (v, s, eps))
    n = max(8, math.ceil(8.0 * period / float(s.min())))
    delta = (np.arange(n) + 0.5) * (period / n) - period / 2  # (m,), the prior's grid

    def log_mix(r: np.ndarray, var: np.ndarray) -> np.ndarray:
        # log((1 - eps) N(r; 0, var) + eps / T)
        gauss = np.log1p(-eps) - 0.5 * r * r / var - 0.5 * np.log(2.0 * math.pi * var)
        return np.logaddexp(gauss, np.log(eps / period))

    r1 = np.asarray(wrap_angle_period(v - delta[None, :], period), dtype=float)  # (n, m)
    l1 = log_mix(r1, s * s).sum(axis=0)  # (m,)
    l0 = float(log_mix(np.asarray(wrap_angle_period(v, period)), s * s + p_tt).sum())
    top = float(l1.max())
    return top + math.log(float(np.mean(np.exp(l1 - top)))) - l0


def sequential_streak(
    d: HeadingDecision, history: Sequence[HeadingDecision], params: FixParams, p_tt: float
) -> list[HeadingDecision]:
    """The rings whose sequential test calls for a recovery at ``d`` (newest first), or
    [] (module docstring): ``d`` a gated corridor fix, and the rings since the last
    agreeing fix (ok or recovered), within ``recover_window_s``, with
    :func:`ring_evidence` (junction rings and rings without evidence skipped), favour a
    jump by B >= 1 / ``recover_alpha``.

    Parameters
    ----------
    d : HeadingDecision
        The current ring's decision (its ``odometry`` and ``predicted``).
    history : sequence of HeadingDecision
        The earlier single-ring decisions, oldest first.
    params : FixParams
        ``recover_alpha``, ``recover_after`` (0: off), ``recover_window_s``,
        ``recover_max_deg``, the sigmas and gross-error rates.
    p_tt : float
        The filter's heading variance at ``d`` (rad^2).

    Returns
    -------
    list of HeadingDecision
        The rings tested, newest first (``d`` first), or [] when no recovery is due.
    """
    alpha = params.recover_alpha
    if alpha <= 0 or params.recover_after <= 0 or d.junction or d.reason != "gated":
        return []
    if not formed(d):
        return []
    if abs(float(wrap_angle(d.measured - d.predicted))) > math.radians(params.recover_max_deg):
        return []
    rings, ev = [], []
    for x in (d, *reversed(history)):
        if x.t < d.t - params.recover_window_s:
            break
        if formed(x) and x.reason != "gated":
            break  # an agreeing fix: the filter's heading was right there
        e = ring_evidence(x, params)
        if e is None:
            continue
        rings.append(x)
        # the candidate carried to the current ring by the dead reckoning
        ev.append((e[0] - x.odometry + d.odometry - d.predicted, e[1], e[2]))
    if not all(math.isfinite(a) for row in ev for a in row):
        return []
    v, s, eps = (np.array(c) for c in zip(*ev, strict=True))
    period = math.pi / 2 if params.right_angles else math.pi
    return rings if jump_log_odds(v, s, eps, p_tt, period) >= math.log(1.0 / alpha) else []


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

    Evidence rings are the formed fixes (ok, gated, recovered) outside unsure
    junctions: a ring that forms no fix (no wall, ambiguous wall or heading, no
    corridor) is skipped, neither breaking nor extending the streak, and so is a ring
    at an :func:`unsure_junction` (oblique corridors, whose fixes can be off by a
    consistent 7-14 deg for several rings, or one direction only, which may be another
    corridor's). An ok or recovered evidence ring ends the streak.

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
    if k <= 0 or d.unsure_junction or d.reason != "gated" or not formed(d):
        return []
    if abs(float(wrap_angle(d.measured - d.predicted))) > math.radians(params.recover_max_deg):
        return []  # as likely another corridor's walls as a bump (recover_max_deg)
    last = [d]
    for x in reversed(history):
        if len(last) >= k or x.t < d.t - params.recover_window_s:
            break
        if not formed(x) or x.unsure_junction:
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
