"""The heading aid's multi-ring window [ours] (``fixes.flm_rings`` > 1; the design is in
:mod:`fuzzyslam.fixes.heading`'s docstring, "Multi-ring FLM").

:class:`MultiRingWindow` keeps the last ``flm_rings`` rings with their DEAD-RECKONING
poses (:class:`fuzzyslam.maps.flm.RecentRings`), forms one multi-ring heading fix every
``flm_fix_every`` rings (0: every ``flm_rings``, disjoint windows) with the noise

    R = sigma^2 * max(1, flm_rings / flm_fix_every)

(sigma = ``sigma_flm_deg`` in a corridor, ``sigma_junction_deg`` scaled alike at a
junction; overlapping windows count each ring's information once), raised to the wall
fit's own standard deviation when that is larger (``flm_fit_sigma``), and keeps the
single-ring watchdog's decisions of the last ``recover_window_s`` seconds (the history
the bump recovery looks at). Between fixes a single-ring decision becomes a row that is
not applied (``between_fixes``; ``gated`` rows stay, they drive the recovery).

In metres of travel [ours] (``flm_window_m`` > 0, real buildings): the window keeps the
rings within ``flm_window_m`` of dead-reckoned travel and a fix is formed every
``flm_fix_travel`` metres, R inflated by flm_window_m / flm_fix_travel: what a window
sees of the walls grows with the travel, not with the rings (a ring every 9 cm in one
building log, every metre in another). With ``flm_fit_scatter`` a fix's sigma comes
from its window's own wall fit, max(sigma_flm, flm_fit_scale q), q = sigma_fit
max(1, Birge ratio) sqrt(K) over the window's K rings, and a window with q above
``flm_fit_max_deg`` forms no fix (``loose_fit``): measured on two building logs, the
error's rms is 1.4-2.5 q up to q = 1 deg, and gross errors dominate beyond.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from fuzzyslam.fixes.heading_measure import HeadingDecision, WallLike, decide_heading_fix
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.references import Reference
from fuzzyslam.maps.flm import RecentRings
from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.slam.events import FilterView


class MultiRingWindow:
    """The multi-ring FLM window of the heading aid (module docstring).

    Parameters
    ----------
    params : FixParams
        ``flm_rings`` (> 1), ``flm_window_s``, ``flm_fix_every``, the sigmas, ``flm_fit_sigma``,
        ``recover_window_s``.
    rings_flm : callable
        ``rings_flm(recent, mounts) -> BeliefMap``: the FLM of a :class:`RecentRings` in the
        newest ring's frame (``RecentRings.flm``).
    wall_direction : callable
        ``wall_direction(flm) -> WallLike or None``: the FLM's wall (Hough).
    """

    def __init__(
        self,
        params: FixParams,
        rings_flm: Callable[[RecentRings, np.ndarray], BeliefMap],
        wall_direction: Callable[[BeliefMap], WallLike | None],
    ) -> None:
        p = params
        self.params = params
        self.rings_flm = rings_flm
        self.wall_direction = wall_direction
        self.recent = RecentRings(p.flm_rings, p.flm_window_s, p.flm_window_m)
        self.fix_every = p.flm_fix_every if p.flm_fix_every > 0 else p.flm_rings
        self.fix_travel = p.flm_fix_travel if p.flm_window_m > 0 else 0.0
        if self.fix_travel > 0:  # windows and fixes in metres of travel
            infl = math.sqrt(max(1.0, p.flm_window_m / self.fix_travel))
        else:
            infl = math.sqrt(max(1.0, p.flm_rings / self.fix_every))
        scale = p.sigma_flm_deg / p.sigma_heading_deg
        # (corridor, junction) sigmas of a multi-ring fix (deg)
        self.sigmas_deg = (p.sigma_flm_deg * infl, p.sigma_junction_deg * scale * infl)
        self.since_fix = 0  # rings since the last multi-ring fix was formed
        self.travelled = 0.0  # dead-reckoned travel (m) since then
        self.single: list[HeadingDecision] = []  # the watchdog's recent decisions
        self.formed = 0  # multi-ring fixes formed

    def push(self, t: float, ring: Any, ekf: FilterView) -> None:
        """Add a ring with the filter's dead-reckoning pose (``ekf.odometry_pose``).

        Parameters
        ----------
        t : float
            The ring's log time (s).
        ring : Ring
            The sonar ring (ranges (M,), max ranges (M,), fov).
        ekf : FilterView
            The filter (its dead reckoning, never corrected by the fixes).
        """
        odo = np.asarray(ekf.odometry_pose, dtype=float)
        self.travelled += self.recent.push(
            t, odo, ring.ranges, ring.max_range, ring.fov, getattr(ring, "mounts", None)
        )
        self.since_fix += 1

    def restart(self, t: float, ring: Any, ekf: FilterView) -> None:
        """Start the window afresh from this ring (after a bump recovery: the older rings
        are from before the bump); the next fix is ``fix_every`` rings later.

        Parameters
        ----------
        t : float
            The ring's log time (s).
        ring : Ring
            The sonar ring.
        ekf : FilterView
            The filter (its dead reckoning).
        """
        self.recent.clear()
        self.recent.push(
            t, ekf.odometry_pose, ring.ranges, ring.max_range, ring.fov,
            getattr(ring, "mounts", None),
        )  # fmt: skip
        self.since_fix = 0
        self.travelled = 0.0

    def remember(self, t: float, d: HeadingDecision) -> None:
        """Keep a single-ring decision in the watchdog's history, dropping those older
        than ``recover_window_s`` before ``t``.

        Parameters
        ----------
        t : float
            The current ring's time (s).
        d : HeadingDecision
            The ring's single-ring decision.
        """
        self.single.append(d)
        horizon = t - self.params.recover_window_s
        while self.single and self.single[0].t < horizon:
            del self.single[0]

    def decide(
        self,
        t: float,
        single: HeadingDecision,
        refs: Sequence[Reference],
        mounts: np.ndarray,
        ekf: FilterView,
        corridor: tuple[Sequence[Reference], str] | None = None,
    ) -> HeadingDecision:
        """The multi-ring fix when one is due (``fix_every`` rings since the last, the
        window at least half full), else ``single`` as a row that is not applied.

        Parameters
        ----------
        t : float
            The ring's log time (s).
        single : HeadingDecision
            The ring's single-ring decision (the watchdog's).
        refs : sequence of Reference
            The map's corridors.
        mounts : ndarray, shape (M, 3)
            The sonars' poses in base_link.
        ekf : FilterView
            The filter (pose (3,), pose covariance (3, 3)).
        corridor : (sequence of Reference, str), optional
            The candidate corridors at the filter's pose, when the caller has them
            (:func:`fuzzyslam.fixes.heading_measure.select_corridor`).

        Returns
        -------
        HeadingDecision
            The multi-ring decision (not yet applied), or ``single`` (``gated``) or its
            ``between_fixes`` row (measured NaN, not accepted).
        """
        if self.fix_travel > 0:  # once the robot has travelled fix_travel since the last
            due = self.travelled >= self.fix_travel and len(self.recent) >= 2
        else:
            due = self.since_fix >= self.fix_every and 2 * len(self.recent) >= self.recent.count
        if not due:
            if single.reason == "gated":
                return single
            return single.replace(measured=math.nan, accepted=False, reason="between_fixes")
        self.since_fix = 0
        self.travelled = 0.0
        self.formed += 1
        p = self.params
        wall = self.wall_direction(self.rings_flm(self.recent, mounts))
        sig_c, sig_j = self.sigmas_deg
        fit = math.degrees(float(getattr(wall, "sigma", math.nan))) if wall is not None else 0.0
        if p.flm_fit_scatter:
            return self._scatter_decision(t, wall, fit, refs, ekf, corridor)
        if p.flm_fit_sigma and math.isfinite(fit) and fit > p.sigma_flm_deg:
            # the tangent fit's own standard deviation (range noise through the fit's
            # Jacobian) when it exceeds the floor: a loose fit weighs less
            k = fit / p.sigma_flm_deg
            sig_c, sig_j = sig_c * k, sig_j * k
        return decide_heading_fix(
            t, wall, refs, ekf.pose, ekf.pose_cov, p, (sig_c, sig_j), corridor
        )

    def _scatter_decision(
        self,
        t: float,
        wall: WallLike | None,
        fit_deg: float,
        refs: Sequence[Reference],
        ekf: FilterView,
        corridor: tuple[Sequence[Reference], str] | None = None,
    ) -> HeadingDecision:
        """The multi-ring decision with R from the wall fit's own scatter
        (``flm_fit_scatter``, see :class:`fuzzyslam.fixes.params.FixParams`): q =
        sigma_fit max(1, Birge) sqrt(K); no fix (``loose_fit``) above ``flm_fit_max_deg``."""
        p = self.params
        birge = float(getattr(wall, "birge", math.nan)) if wall is not None else math.nan
        q = fit_deg * max(1.0, birge if math.isfinite(birge) else 1.0) * math.sqrt(len(self.recent))
        if (
            wall is not None
            and math.isfinite(wall.angle)
            and not (math.isfinite(q) and q <= p.flm_fit_max_deg)
        ):
            strength = float(wall.strength)
            return HeadingDecision(
                t, -1, math.nan, float(ekf.pose[2]), False, "loose_fit", strength
            )
        sig_c, sig_j = self.sigmas_deg
        k = max(1.0, p.flm_fit_scale * q / p.sigma_flm_deg) if math.isfinite(q) else 1.0
        sig = (sig_c * k, sig_j * k)
        return decide_heading_fix(t, wall, refs, ekf.pose, ekf.pose_cov, p, sig, corridor)
