"""Heading fixes from the frozen FGM: the paper's contribution (docs/models.md sec. 9; its sec. 4).

A wall of world direction ``t_ref`` (the reference angle of the corridor the robot is
in, from the FGM) is seen in the robot frame at ``t_local = t_ref - theta`` (the Hough
peak of the FLM). Both are lines, so defined mod pi, hence the measurement

    theta = t_ref - t_local   (mod pi; mod pi/2 where walls meet at right angles)

is one of a comb of candidates theta_0 + k * period; the one nearest the predicted
heading is taken. It is refused when the second nearest is also plausible
(|d2| < n sigma, sigma^2 = P_tt + R), then gated on its normalised innovation squared
NIS = (theta - theta_pred)^2 / (P_tt + R) against chi-square with 1 dof, and applied
as the direct measurement h(x) = theta, H = [0 0 1 0 ...] (Probabilistic Robotics
sec. 3.3; the EKF's ``update_robot``).

Corners and junctions [ours]: outside every corridor region (or where regions of
different angles overlap) the regions within ``junction_margin`` all offer their
comb; the candidate nearest the prediction wins unless another is also plausible
(``ambiguous_heading``), and the fix has the larger measured noise
``sigma_junction_deg``. Without it a bump in a corner went uncorrected for the whole
corner (measured on paper_bumps.yaml: 40 cm drift, lamps duplicated).

Bumps [ours]: ``recover_after`` consecutive gated single-ring fixes that agree mean the
filter, not the map, is wrong: the robot covariance is inflated (heading by v^2,
position by (v d)^2, d the path since the last accepted fix, and the heading-position
covariance by the lever the bump left: v^2 J L, L the path since the bump,
``fixes.bump_recovery.bump_position``) and the streak's fix applied
(``fixes.bump_recovery.recovery_streak``), which so moves the position with the heading.
A bump is a step between the true and the dead-reckoning headings, so the agreement is
tested on the offsets measured - odometry heading (a constant plus each ring's noise;
the filter's own heading moves with the lamp updates), by a chi-square test on their
weighted scatter (``recover_spread_p``), and the fix applied is their weighted mean
added to the current dead-reckoning heading. A recovery is also due as soon as the
rings since the last agreeing fix favour a jump by a Bayes factor of 1 /
``recover_alpha`` (the sequential test, ``fixes.bump_recovery.sequential_streak``:
each corridor ring weighed by its own wall fit's sigma and gross-error rate, the
ambiguous_wall rings' dominant walls included as weak evidence; no ring decides
alone, a second agreeing one, or ambiguous rings leaning the same way, can); the fix
applied is then the formed rings' weighted mean, and the bump is placed midway between
the last agreeing ring and the test's first ring. Rings forming no fix (no wall, ambiguous
wall, no corridor) neither break nor extend a streak (``recover_window_s`` bounds its
span), and rings at unsure junctions are no evidence: oblique ones (candidate corridors
not at right angles), where the FLM's wall was measured 7-14 deg off for 3-6 rings in a
row (paper_bumps.yaml, the corners of the 70-degree corridor, 4 of 5 seeds), which
consistency cannot tell from a bump, and those whose candidates all run one way (no
junction the map knows of: the walls seen may be a corridor's the map has no reference
for; ``fixes.bump_recovery.unsure_junction``). A bump is not in the covariance, so only
the heading fixes can vouch for the pose from which a new lamp is initialised: the aid flags
``pose_suspect`` (``run`` then creates no new lamp, it would be a duplicate) unless the
latest ring's fix agrees with the prediction (NIS <= ``suspect_chi2``), and from a
disagreement (gated, NIS above ``suspect_chi2``, or a recovery) until a fix that agrees
is applied (``_update_suspicion``).

Multi-ring FLM [ours] (``fixes.flm_rings`` > 1, and a multi-ring FLM builder given; the
window is :class:`fuzzyslam.fixes.multi_ring.MultiRingWindow`):
one ring's wall direction scatters by about 1.5 deg (echo noise, short arcs); the FLM of
the last ``flm_rings`` rings (:class:`fuzzyslam.maps.flm.RecentRings`) gives about 0.4
deg. The rings are placed by their DEAD-RECKONING relative poses (``EkfSlam.odometry_pose``,
never corrected): over 2 s odometry is accurate to a fraction of a degree and, unlike
the filter's pose, it does not jump at lamp updates or at the heading fixes themselves
(a fix would otherwise enter the windows of the next fixes: the measurement would not
be independent of the state it corrects). Windows that share rings have correlated
errors, so one multi-ring fix is formed every ``flm_fix_every`` rings (0: every
``flm_rings``, disjoint windows) with R = sigma_flm^2 * max(1, flm_rings / flm_fix_every)
(overlapping windows: each ring's information counted once), larger when the wall's
tangent fit reports a larger standard deviation (``flm_fit_sigma``). The single-ring decision is
still made on every ring as a watchdog: its gated streaks drive the bump recovery (a
bump makes the window's older rings disagree with the newer ones, so the multi-ring FLM
cannot see it quickly), after which the window restarts from the current ring; it also
sets ``pose_suspect``. Single-ring decisions are not applied between multi-ring fixes
(reason ``between_fixes``, or ``gated`` when the watchdog refused it).

Reasons recorded per ring (``heading_fixes.csv``): ``ok``, ``recovered``, ``no_wall``
(no Hough peak), ``weak_peak``, ``ambiguous_wall`` (the FLM's peaks disagree: junction,
open space), ``no_corridor``, ``ambiguous_corridor`` (two regions with different
reference angles, junctions off), ``ambiguous_reference`` (in a region the map stage
flagged, no other within the junction margin), ``ambiguous_heading`` (two candidates both
plausible), ``gated``, ``loose_fit`` (a multi-ring window whose own wall fit is too
loose, ``fixes.flm_fit_scatter``).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import is_dataclass, replace
from typing import Any

import numpy as np

from fuzzyslam.fixes.base import FixAid
from fuzzyslam.fixes.bump_recovery import (
    bump_position,
    formed,
    recovery_streak,
    sequential_streak,
    streak_offset,
    unsure_junction,
)
from fuzzyslam.fixes.heading_measure import (  # the paper's measurement; re-exported here
    HEADING_FIELDS,
    FlmSource,
    HeadingDecision,
    WallLike,
    decide_heading_fix,
    nearest_candidate,
    select_corridor,
)
from fuzzyslam.fixes.multi_ring import MultiRingWindow
from fuzzyslam.fixes.off_map import OffMapWatch
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.references import Reference
from fuzzyslam.fixes.summaries import HeadingSummary
from fuzzyslam.maps.flm import RecentRings
from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.se2 import wrap_angle
from fuzzyslam.slam.events import FilterView
from fuzzyslam.slam.health import chi2_quantile

__all__ = ["HEADING_FIELDS", "FlmSource", "HeadingDecision", "HeadingFixAid", "WallLike",
           "decide_heading_fix", "nearest_candidate", "select_corridor"]  # fmt: skip


class HeadingFixAid(FixAid):
    """Plug-in of ``fuzzyslam run``: a heading fix per sonar ring from ``start_time`` on.

    ``flm_source(ring, mounts) -> BeliefMap`` (robot frame) and ``wall_direction(flm) ->
    WallLike`` are the maps stage's FLM builder and Hough (injected, so that tests can
    use synthetic ones). ``rings_flm(recent, mounts) -> BeliefMap`` builds the FLM of a
    :class:`RecentRings` (``RecentRings.flm``); with it and ``params.flm_rings`` > 1 the
    fixes come from multi-ring FLMs (module docstring), without it from single rings.
    """

    kind = "heading"
    csv_name = "heading_fixes.csv"
    csv_fields = HEADING_FIELDS

    def __init__(
        self,
        refs: Sequence[Reference],
        params: FixParams,
        flm_source: Callable[[Any, np.ndarray], BeliefMap],
        wall_direction: Callable[[BeliefMap], WallLike | None],
        start_time: float = 0.0,
        rings_flm: Callable[[RecentRings, np.ndarray], BeliefMap] | None = None,
    ) -> None:
        super().__init__(params, start_time)
        self.refs = list(refs)
        self.flm_source = flm_source
        self.wall_direction = wall_direction
        self.decisions: list[HeadingDecision] = []
        self.recoveries = 0
        # the robot's position uncertainty against the corridor choice (``trouble``)
        self.position_sigma_max = 0.0
        self.position_unresolved_at: float | None = None
        # the estimate against the frozen map's free space (fixes/off_map.py; ``trouble``),
        # given by fixes/aids.py when the map is at hand
        self.off_map: OffMapWatch | None = None
        self._last_ok_xy: np.ndarray | None = None  # position at the last accepted fix
        # the last formed fix disagreed with the prediction (NIS above suspect_chi2, or
        # gated): ``run`` then creates no new lamp (it would be a duplicate)
        self.pose_suspect = False
        self._disagreed = False  # a disagreement not yet resolved by an applied fix
        # the multi-ring window (fixes/multi_ring.py): with rings_flm and flm_rings > 1
        self.window = (
            MultiRingWindow(params, rings_flm, wall_direction)
            if rings_flm is not None and params.flm_rings > 1
            else None
        )
        self._ahead: tuple[Any, WallLike | None] | None = None  # (ring, wall): take_ahead

    def ahead(self, ring: Any, mounts: np.ndarray) -> tuple[WallLike | None] | None:
        """The ring's single-ring wall, ``wall_direction(flm_source(ring, mounts))``: the
        ring and the mounts alone decide it, so it may be computed before the filter
        reaches the ring (``FixAid.ahead``; in slam/prefetch.py's child process, on
        another core). It is the FLM and Hough of :meth:`on_ring`, whose answer is the
        same whichever process computed it; without the Hough plane (``plane``, for the
        maps' figures only, 100 KB a ring through the pipe: 0.14 s of pickling a run).

        Parameters
        ----------
        ring : Ring
            The sonar ring.
        mounts : ndarray, shape (M, 3)
            The sonars' poses in base_link.

        Returns
        -------
        (WallLike or None,) or None
            The wall (None: no wall found), in a 1-tuple; None without an FLM source.
        """
        if self.flm_source is None or self.wall_direction is None:
            return None
        wall = self.wall_direction(self.flm_source(ring, mounts))
        if is_dataclass(wall) and getattr(wall, "plane", None) is not None:
            wall = replace(wall, plane=None)  # decide_heading_fix reads none of it
        return (wall,)

    def take_ahead(self, ring: Any, value: tuple[WallLike | None]) -> None:
        """:meth:`ahead`'s answer for ``ring``, used by the next :meth:`on_ring` if it is
        given that ring (``FixAid.take_ahead``).

        Parameters
        ----------
        ring : Ring
            The ring.
        value : (WallLike or None,)
            :meth:`ahead`'s answer.
        """
        self._ahead = (ring, value[0])

    def on_ring(self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView) -> None:
        """Form the ring's heading measurement (the paper's, on its FLM or the multi-ring
        window's), decide it and apply it to the filter (module docstring).

        Parameters
        ----------
        t : float
            The ring's log time (s).
        ring : Ring
            The sonar ring (ranges (M,), max ranges (M,), fov).
        mounts : ndarray, shape (M, 3)
            The sonars' poses in base_link.
        ekf : FilterView
            The filter (its pose, covariance, dead reckoning, ``update_robot``).
        """
        ahead, self._ahead = self._ahead, None
        if not self.started(t):
            return
        window = self.window
        if window is not None:
            window.push(t, ring, ekf)
        pose = ekf.pose
        x0, y0 = float(pose[0]), float(pose[1])
        self._watch_position(t, ekf.pose_cov, x0, y0)
        odo_heading = float(ekf.odometry_pose[2])
        period = math.pi / 2 if self.params.right_angles else math.pi
        cands, why = select_corridor(pose[:2], self.refs, period, self.params.junction_margin)
        if not cands:  # no FLM or Hough needed (junctions, open space)
            self.decisions.append(
                HeadingDecision(
                    t, -1, math.nan, pose[2], False, why, math.nan, odometry=odo_heading
                )
            )
            if window is not None:
                window.single.append(self.decisions[-1])  # skipped by recovery_streak
            return
        if ahead is not None and ahead[0] is ring:  # computed ahead (take_ahead)
            wall = ahead[1]
        else:
            wall = self.wall_direction(self.flm_source(ring, mounts))
        corridor = (cands, why)  # asked once per ring, at this pose
        d = decide_heading_fix(
            t, wall, self.refs, pose, ekf.pose_cov, self.params, corridor=corridor
        )
        junction = why == "junction"
        d = d.replace(odometry=odo_heading, unsure_junction=junction and unsure_junction(cands),
                    x=x0, y=y0)  # fmt: skip
        history = window.single if window is not None else self.decisions
        recover = d.reason == "gated"
        streak = recovery_streak(d, history, self.params) if recover else []
        if recover and not streak:  # the sequential test (bump_recovery's docstring)
            streak = sequential_streak(d, history, self.params, float(ekf.pose_cov[2, 2]))
        if streak:
            # consistent gated fixes: the filter, not the map, is wrong (an unseen bump).
            # The fix applied is the streak's: their common offset from dead reckoning
            # (weighted mean) added to the current dead-reckoning heading, with
            # R = 1 / sum(1 / sigma_i^2) (one ring's fix can be 3 deg off at a corner, and
            # a heading left that far off is gated by the multi-ring fixes that follow).
            # Covariance inflation (fading memory, Simon, "Optimal state estimation",
            # sec. 7.4) makes the prediction admit the innovation v: P_tt += v^2. The
            # heading was wrong by up to |v| somewhere along the path since the last
            # accepted fix (length d), so the position is off by up to |v| d in an unknown
            # direction: P_xx, P_yy += (v d)^2, which lets the lamps re-associate. The
            # heading error came in one step at the bump, between the streak's first ring
            # and the last agreeing ring before it (bump_recovery.bump_position), and the
            # position has since drifted by v J (p - p_bump), J the 90-degree turn: the
            # inflation's heading column carries that lever, Q += v^2 g g^T, g = (J L, 1),
            # L = p - p_bump, so the fix moves the position with the heading.
            offset, sigma, _ = streak_offset([x for x in streak if formed(x)])
            d = d.replace(measured=float(wrap_angle(d.odometry + offset)), sigma=sigma)
            v = float(wrap_angle(d.measured - d.predicted))
            dist = (
                float(np.hypot(*(pose[:2] - self._last_ok_xy)))
                if self._last_ok_xy is not None
                else 0.0
            )
            q_xy = (v * dist) ** 2
            lever = pose[:2] - bump_position(streak, history, self._last_ok_xy)
            g = np.array([-lever[1], lever[0], 1.0])
            ekf.inflate_robot(np.diag([q_xy, q_xy, 0.0]) + v * v * np.outer(g, g))
            d = d.replace(accepted=True, reason="recovered")
            self.recoveries += 1
            if window is not None:  # the window's older rings are from before the bump
                window.restart(t, ring, ekf)
        single = d
        if window is not None:
            window.remember(t, d)  # the watchdog's memory: what recovery_streak may see
            if d.reason != "recovered":
                d = window.decide(t, d, self.refs, mounts, ekf, corridor)
        if d.accepted:
            res = ekf.update_robot(
                [d.measured], [[d.sigma * d.sigma]], [2], gate_chi2=self.params.gate_chi2
            )
            d = d.replace(nis=float(res.nis))
            if not res.accepted:
                d = d.replace(accepted=False, reason="gated")
            else:
                self._last_ok_xy = ekf.pose[:2]
        self._update_suspicion(single, d)
        self.decisions.append(d.replace(x=x0, y=y0))
        self._watch_position(t, ekf.pose_cov)  # a recovery inflates it

    def _watch_position(
        self, t: float, cov: np.ndarray, x: float | None = None, y: float | None = None
    ) -> None:
        """Track the position's largest standard deviation, and the first ring at which
        its 99 % ellipse's semi-major axis, sqrt(chi2_2(0.99) lambda_max(P_xy)), exceeds
        ``junction_margin`` (``trouble``); asked before and after the ring's fix.

        The corridor a fix is taken from is chosen at the filter's mean position
        (``select_corridor``), regions within ``junction_margin`` of it competing; once
        the filter itself puts the robot farther than that from its mean, a region it
        does not consider may be the one it is in, and the fixes rest on a guess. This
        happens without lamps, when a recovery inflates the position by the drift a
        wrong heading may have caused, (v d)^2, over a long d: after a false 90-degree
        recovery on the quick world's dark lap (seeds 9, 10, 12 before junction rings
        of one direction were ruled out as bump evidence: sigma 3.5-6.2 m, errors of
        10-19 m), or a 10-degree bump in a corridor the map has no reference for (seed
        10 since: sigma 1.26 m, error up to 69 cm).

        Parameters
        ----------
        t : float
            The ring's log time (s).
        cov : ndarray, shape (3, 3)
            The robot's covariance.
        x, y : float, optional
            The estimated position, for the off-map watch (``off_map``).
        """
        lam = self._track_position_sigma(cov)
        if self.off_map is not None and x is not None and y is not None:
            self.off_map.observe(t, x, y, lam)
        margin = self.params.junction_margin
        if (
            self.position_unresolved_at is None
            and margin > 0
            and chi2_quantile(0.99, 2) * lam > margin * margin
        ):
            self.position_unresolved_at = t

    def _track_position_sigma(self, cov: np.ndarray) -> float:
        """Keep ``position_sigma_max`` (the summary's ``position_sigma_max_m``) and return
        lambda_max of the position's 2x2 block of ``cov`` (3, 3)."""
        a, b, c = float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1])
        lam = 0.5 * (a + c) + math.hypot(0.5 * (a - c), b)  # the 2x2 block's largest
        self.position_sigma_max = max(self.position_sigma_max, math.sqrt(max(lam, 0.0)))
        return lam

    def trouble(self) -> tuple[str, float] | None:
        """The aid's finding for the run's ``filter_health`` (slam/run_results.py):
        ("position_unresolved", the time) once the position's 99 % ellipse outgrew
        ``junction_margin`` (``_watch_position``), else ("pose_off_map", the time) once
        most rings of a minute put the estimate farther from the map's free space than
        its uncertainty allows (fixes/off_map.py), else None.

        Returns
        -------
        (str, float) or None
        """
        if self.position_unresolved_at is not None:
            return "position_unresolved", self.position_unresolved_at
        if self.off_map is not None and self.off_map.found_at is not None:
            return "pose_off_map", self.off_map.found_at
        return None

    def _agrees(self, d: HeadingDecision) -> bool:
        """A formed fix within the gate whose NIS is at most ``suspect_chi2``."""
        return d.reason == "ok" and d.nis <= self.params.suspect_chi2

    def _disagrees(self, d: HeadingDecision) -> bool:
        """A formed fix that is gated or whose NIS exceeds ``suspect_chi2``."""
        return d.reason == "gated" or (d.reason == "ok" and d.nis > self.params.suspect_chi2)

    def _update_suspicion(self, single: HeadingDecision, applied: HeadingDecision) -> None:
        """``pose_suspect``: may a lamp be initialised from the current pose?

        Only from a pose whose heading the sonar confirmed (module docstring, "Bumps").
        An unseen bump is, by definition, not in the covariance, so no covariance gate
        (association, the duplicate guard ``new_lamp_chi2``) can tell a lamp seen from a
        wrongly turned pose from a new one; a lamp at range r initialised with a heading
        error e lands r e away (10 deg at 1.5 m: 26 cm, outside the association gate for
        good: a permanent duplicate). So the map grows only on positive evidence:

        - a disagreement (the ring's fix gated, or NIS > ``suspect_chi2``; single-ring
          watchdog or applied fix) holds until a fix that AGREES is APPLIED (accepted by
          the filter with NIS <= ``suspect_chi2``). A single-ring decision between
          multi-ring fixes is not applied, so the state it found inconsistent is
          unchanged: one noisy ring (about 1.5 deg) near the prediction does not refute
          the gated one (measured on paper_bumps.yaml seed 2: such a ring cleared the
          flag 0.25 s after a bump, and three lamps were duplicated). A recovery is
          itself a disagreement: it applies a fix the gate refused, on the evidence of
          ``recover_after`` rings, which can be wrong (seed 5: rings in a turn triggered
          one that turned a correct heading 9 deg, and a lamp seen next was duplicated);
          the pose is trusted again once a later fix agrees with the recovered heading;
        - and the latest ring must itself confirm the heading (an agreeing fix). A ring
          that forms no fix (no wall, ambiguous wall, junction) confirms nothing, so
          frames after it wait: the camera can see a bump one ring before the sonar does
          (seed 2: two lamps duplicated 0.4 s after a bump whose first ring had an
          ambiguous wall).

        Before the aid's start time ``pose_suspect`` stays False (lamp-only SLAM).
        """
        if applied.accepted and self._agrees(applied):
            self._disagreed = False
        if self._disagrees(single) or self._disagrees(applied) or applied.reason == "recovered":
            self._disagreed = True
        self.pose_suspect = self._disagreed or not self._agrees(single)

    def update_rows(self) -> list[dict[str, Any]]:
        """The EKF update attempts, as rows of run's updates.csv (docs/contracts.md sec. 2):
        fixes that reached the filter (accepted, recovered, or refused by its NIS gate).

        Returns
        -------
        list of dict
            One row per attempt: t, kind, nis, accepted, innovation.
        """
        return [
            {
                "t": d.t,
                "kind": self.kind,
                "id": d.corridor,
                "dof": 1,
                "nis": d.nis,
                "accepted": int(d.accepted),
                "v0": float(wrap_angle(d.measured - d.predicted)),
                "v1": None,
                "v2": None,
            }
            for d in self.decisions
            if d.reason in ("ok", "recovered", "gated")
        ]

    def summary(self) -> HeadingSummary:
        """The aid's entry in run's summary.

        Returns
        -------
        HeadingSummary
            Rings decided and before the start, fixes accepted, bump recoveries, the
            multi-ring window's use, decisions by reason, the accepted fixes' mean NIS.
        """
        reasons = Counter(d.reason for d in self.decisions)
        accepted = [d for d in self.decisions if d.accepted]
        nis = np.array([d.nis for d in accepted]) if accepted else np.zeros(0)
        return HeadingSummary(
            rings=len(self.decisions),
            before_start=self.before_start,
            accepted=len(accepted),
            recoveries=self.recoveries,
            flm_rings=self.window.recent.count if self.window is not None else 1,
            multi_ring_fixes_formed=self.window.formed if self.window is not None else 0,
            reasons=dict(sorted(reasons.items())),
            mean_nis=float(nis.mean()) if nis.size else None,
            position_sigma_max_m=round(self.position_sigma_max, 4),
            position_unresolved_at=self.position_unresolved_at,
        )

    def messages(self, topics: Any, start: float | None = None) -> list:
        """The heading fixes for estimates.mcap (``topics.heading_fixes``, fixes/viewer.py),
        and the map (``viewer_map``, stamped ``start``) when this aid shows it.

        Parameters
        ----------
        topics : TopicParams
            The config's topics (``heading_fixes`` and the map's).
        start : float or None
            The log's start (s), the map messages' stamp.

        Returns
        -------
        list
            The messages (topic, stamp, message) for the run's estimates.mcap.
        """
        from fuzzyslam.fixes.viewer import heading_fix_messages, map_messages

        angles = {r.id: r.angle for r in self.refs}
        fixes = heading_fix_messages(self.decisions, angles, topics.heading_fixes)
        return map_messages(self.viewer_map, topics, start) + fixes
