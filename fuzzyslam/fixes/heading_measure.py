"""The paper's heading measurement (docs/models.md sec. 7; fixes/heading.py has the
aid that applies it, with the multi-ring window and bump recovery): which corridor the
robot is in (``select_corridor``), the candidate heading nearest the prediction
(``nearest_candidate``), the decision for one FLM wall direction (``decide_heading_fix``,
NIS against chi-square with 1 dof), the FLM cache (``FlmSource``) and heading_fixes.csv.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.references import Reference, corridors_at, corridors_near
from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.se2 import wrap_angle, wrap_angle_period
from fuzzyslam.stamps import format_time

HEADING_FIELDS = ("t", "corridor", "measured", "predicted", "accepted", "reason", "strength")


class WallLike(Protocol):
    """What the FLM's Hough gives (``maps.hough.WallDirection``)."""

    angle: float
    strength: float
    ambiguous: bool


@dataclass(frozen=True)
class HeadingDecision:
    """One ring's heading fix: measured theta (nan when not formed), why (not) applied."""

    t: float
    corridor: int
    measured: float
    predicted: float
    accepted: bool
    reason: str
    strength: float
    nis: float = math.nan
    sigma: float = math.nan  # standard deviation (rad) of the measurement when formed
    # the dead-reckoning heading at the ring (EkfSlam.odometry_pose; the filter's when
    # absent): the bump recovery's reference for the measurements' consistency
    odometry: float = math.nan
    # at a junction whose rings are no bump evidence (fixes/bump_recovery.py
    # unsure_junction: candidate corridors not at right angles, or all one way)
    unsure_junction: bool = False
    # the filter's position at the ring, before the fix (where a viewer draws it)
    x: float = math.nan
    y: float = math.nan
    # the wall fit's own standard deviation (rad; NaN without the tangent refinement)
    # and, for a ring refused as ambiguous_wall in one corridor, the comb candidate its
    # dominant wall gives nearest the prediction (rad): the bump test's weak evidence
    # (fixes/bump_recovery.py, jump_log_odds)
    fit_sigma: float = math.nan
    candidate: float = math.nan
    # formed at a junction (R = sigma_junction_deg)
    junction: bool = False

    def replace(self, **changes: Any) -> HeadingDecision:
        """``dataclasses.replace(self, **changes)``, the same decision (every field is an
        ``__init__`` field, there is no ``__post_init__``) at a fifth of its cost: the
        fields copied at once, not passed one by one through ``__init__`` (the heading aid
        makes three or four a ring).

        Parameters
        ----------
        **changes
            New values of fields.

        Returns
        -------
        HeadingDecision
        """
        if type(self) is not HeadingDecision or not changes.keys() <= _DECISION_FIELDS:
            return dataclasses.replace(self, **changes)  # (its TypeError for a non-field)
        new = object.__new__(HeadingDecision)
        fields = new.__dict__
        fields.update(self.__dict__)
        fields.update(changes)
        return new

    def row(self) -> list[str]:
        """The decision as a row of heading_fixes.csv.

        Returns
        -------
        list of str
            t (nine decimals), corridor, measured, predicted, accepted, reason, strength.
        """

        def num(v: float) -> str:
            return "" if not np.isfinite(v) else f"{v:.9g}"

        return [
            format_time(self.t),
            str(self.corridor),
            num(self.measured),
            num(self.predicted),
            str(int(self.accepted)),
            self.reason,
            num(self.strength),
        ]


_DECISION_FIELDS = frozenset(f.name for f in dataclasses.fields(HeadingDecision))


def nearest_candidate(theta0: float, predicted: float, period: float) -> tuple[float, float, float]:
    """Among theta0 + k * period, the candidate nearest ``predicted``.

    Parameters
    ----------
    theta0 : float
        One member of the comb (rad).
    predicted : float
        The predicted heading (rad).
    period : float
        The comb's period (rad): pi, or pi / 2 with right angles.

    Returns
    -------
    theta, d1, d2 : float
        The candidate wrapped to (-pi, pi], its distance to the prediction
        (|d1| <= period / 2) and the distance of the second nearest (period - |d1|).
    """
    d = float(wrap_angle_period(theta0 - predicted, period))
    theta = float(wrap_angle(predicted + d))
    return theta, abs(d), period - abs(d)


def select_corridor(
    xy: Sequence[float], refs: Sequence[Reference], period: float, junction_margin: float = 0.0
) -> tuple[list[Reference], str]:
    """The candidate corridors at ``xy``: (references, "" | "junction" | why none).

    Regions the map stage flagged (a room, a stub, two wall directions alike) are no
    corridor: they offer no angle and, as for the laser's lines
    (:mod:`fuzzyslam.fixes.scan_heading`), the robot in one alone is outside every
    corridor. Inside one region, or overlapping regions whose reference angles agree mod
    ``period`` within 1 degree: the strongest one. Regions that disagree (a junction):
    ``ambiguous_corridor``, or, with ``junction_margin`` > 0, all of them ("junction").
    Outside every region: ``no_corridor`` (``ambiguous_reference`` in a flagged one),
    or, with ``junction_margin`` > 0, the regions within that distance (a corner,
    "junction"), all of whose angles then compete in :func:`decide_heading_fix`.

    Parameters
    ----------
    xy : sequence of float, shape (2,)
        The predicted position (m).
    refs : sequence of Reference
        The map's corridor references.
    period : float
        Angles agree mod this period (rad).
    junction_margin : float
        Distance (m) within which regions near ``xy`` still count (0: off).

    Returns
    -------
    references : list of Reference
        The candidates (empty when none).
    why : str
        "", "junction", or the reason there is none.
    """
    regions = corridors_at(xy, refs)
    inside = [r for r in regions if not r.ambiguous]
    if not inside:
        near = corridors_near(xy, refs, junction_margin) if junction_margin > 0 else []
        near = [r for r in near if not r.ambiguous]
        if near:
            return near, "junction"
        return [], "ambiguous_reference" if regions else "no_corridor"
    if len(inside) > 1:
        a0 = inside[0].angle
        spread = [abs(float(wrap_angle_period(r.angle - a0, period))) for r in inside]
        if max(spread) > math.radians(1.0):
            return (inside, "junction") if junction_margin > 0 else ([], "ambiguous_corridor")
    return [max(inside, key=lambda r: r.strength)], ""


def decide_heading_fix(
    t: float,
    wall: WallLike | None,
    refs: Sequence[Reference],
    pose: np.ndarray,
    pose_cov: np.ndarray,
    params: FixParams,
    sigmas_deg: tuple[float, float] | None = None,
    corridor: tuple[Sequence[Reference], str] | None = None,
) -> HeadingDecision:
    """Form, check and gate the heading measurement of one ring (module docstring).

    With several candidate corridors (a corner, ``fixes.junction_margin`` > 0) every
    reference's comb t_ref - t_local + k period competes: the candidate nearest the
    prediction is taken, refused as ``ambiguous_heading`` when the next one (of any
    comb) is also within ``ambiguity_sigmas`` sqrt(P_tt + R); such a fix has the
    (larger, measured) noise ``sigma_junction_deg``. The decision's ``sigma`` is the R used.
    ``sigmas_deg``: (corridor, junction) standard deviations replacing
    (``sigma_heading_deg``, ``sigma_junction_deg``), e.g. for a multi-ring FLM.

    Parameters
    ----------
    t : float
        The ring's log time (s).
    wall : WallLike or None
        The FLM's dominant wall direction (angle, strength) in the robot frame.
    refs : sequence of Reference
        The map's corridor references.
    pose : ndarray, shape (3,)
        The filter's pose.
    pose_cov : ndarray, shape (3, 3)
        Its covariance.
    params : FixParams
        The fixes' constants.
    sigmas_deg : (float, float), optional
        Standard deviations (deg) replacing the configured ones.
    corridor : (sequence of Reference, str), optional
        :func:`select_corridor`'s answer at ``pose`` when the caller has it already (the
        aid asks once per ring; default: asked here).

    Returns
    -------
    HeadingDecision
        The measurement, the prediction, whether it is to be applied and why.
    """
    predicted = float(pose[2])
    if wall is None or not np.isfinite(wall.angle):
        return HeadingDecision(t, -1, math.nan, predicted, False, "no_wall", math.nan)
    strength = float(wall.strength)
    if strength < params.min_strength:
        return HeadingDecision(t, -1, math.nan, predicted, False, "weak_peak", strength)
    period = math.pi / 2 if params.right_angles else math.pi
    if corridor is None:
        corridor = select_corridor(pose[:2], refs, period, params.junction_margin)
    cands, why = corridor
    fit = float(getattr(wall, "sigma", math.nan))
    # two wall directions in one FLM (a corner) disqualify it, unless the corner's
    # corridors all compete (junction_walls): the strongest wall is then one of theirs
    if wall.ambiguous and not (why == "junction" and params.junction_walls):
        cand = math.nan
        if why == "" and cands:  # one corridor: its candidate, kept as weak bump evidence
            cand = nearest_candidate(cands[0].angle - float(wall.angle), predicted, period)[0]
        return HeadingDecision(
            t, -1, math.nan, predicted, False, "ambiguous_wall", strength,
            fit_sigma=fit, candidate=cand,
        )  # fmt: skip
    if not cands:
        return HeadingDecision(t, -1, math.nan, predicted, False, why, strength)
    if sigmas_deg is None:
        sigmas_deg = (params.sigma_heading_deg, params.sigma_junction_deg)
    junction = why == "junction"
    sig = sigmas_deg[1] if junction else sigmas_deg[0]
    sigma = math.radians(sig)
    # every candidate corridor's nearest comb member, sorted by distance to the prediction
    combs = sorted(
        ((nearest_candidate(r.angle - float(wall.angle), predicted, period), r) for r in cands),
        key=lambda c: c[0][1],
    )
    (theta, d1, d2), ref = combs[0]
    for (th, dk, _), _r in combs[1:]:
        if abs(float(wrap_angle(th - theta))) > math.radians(1.0):
            d2 = min(d2, dk)  # a different heading another corridor would give
    var = float(pose_cov[2, 2]) + sigma**2
    nis = d1 * d1 / var
    if d2 < params.ambiguity_sigmas * math.sqrt(var):
        why = "ambiguous_heading"
    elif nis > params.gate_chi2:
        why = "gated"
    else:
        why = "ok"
    return HeadingDecision(
        t, ref.id, theta, predicted, why == "ok", why, strength, nis, sigma,
        fit_sigma=fit, candidate=theta, junction=junction,
    )  # fmt: skip


class FlmSource:
    """Builds the FLM of a ring once, shared by every aid that needs it on that ring."""

    def __init__(self, build: Callable[[Any, np.ndarray], BeliefMap]) -> None:
        self._build = build
        self._key: tuple[int, float] | None = None
        self._flm: BeliefMap | None = None

    def __call__(self, ring: Any, mounts: np.ndarray) -> BeliefMap:
        key = (id(ring), float(ring.t))
        if key != self._key or self._flm is None:
            self._flm = self._build(ring, mounts)
            self._key = key
        return self._flm

    def seed(self, ring: Any, flm: BeliefMap) -> None:
        """Take ``flm`` as the ring's FLM, built elsewhere of the same ring and mounts (in
        slam/prefetch.py's child process: ``fixes.base.FlmAhead``).

        Parameters
        ----------
        ring : Ring
            The ring (the object the aids will be given).
        flm : BeliefMap
            Its FLM.
        """
        self._flm, self._key = flm, (id(ring), float(ring.t))
