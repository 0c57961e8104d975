"""The full-pose fix plug-in of ``fuzzyslam run`` (docs/models.md sec. 10): per ring, the
correlative match of :mod:`fuzzyslam.fixes.pose_match` around the filter's prediction,
applied as a direct measurement of the pose (``EkfSlam.update_robot``, NIS-gated).

Correlated errors [ours]: successive matches see the same walls from nearly the same
place, so their errors are correlated; the match covariance is inflated by the sum of
their autocorrelations (:func:`cov_inflation`: a fixed ``pose_cov_scale`` for rings at a
fixed rate, or from the travel between matches and the errors' correlation length
``pose_corr_distance``).

Relocalisation [ours] (``pose_recover_after`` > 0): after an unmodelled disturbance (a
jump of the pose stream, a systematic odometry error along a corridor that no match
could pin) the filter can be confidently wrong by more than its 3-sigma search window:
the likelihood's mode then lies on the window's edge or outside it (``edge``,
``no_match``). Such a ring is matched again: centred on the lattice's best pose (an
edge), then over windows 3, 9, ... times wider, up to
the widest (``pose_window_max``, ``pose_window_max_deg``). A match found there that the
NIS gate refuses is evidence that the filter, not the match, is wrong only when it is
repeated: when
``pose_recover_after`` consecutive gated matches, spread over at least the errors'
correlation length ``pose_corr_distance``, imply the same correction of the dead
reckoning (the world-from-odometry transform pose_i * inv(odo_i) agrees between
successive ones within the chi-square gate of their summed covariances), the robot
covariance is inflated by the innovation (P_rr += diag(v^2), fading memory: Simon,
"Optimal state estimation", sec. 7.4) and the match applied (reason ``recovered``).
"""

from __future__ import annotations

import itertools
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from fuzzyslam.fixes.base import FixAid, FlmAhead
from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.pose_match import PoseMatch, PoseMatcher, flm_evidence
from fuzzyslam.fixes.summaries import PoseSummary
from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.se2 import between, compose, wrap_angle
from fuzzyslam.slam.events import FilterView
from fuzzyslam.stamps import format_time

# filter_health's finding (PoseFixAid.trouble): a window of match attempts in which more
# than this share left the pose unpinned (flat or multimodal likelihood)
AMBIGUOUS_WINDOW = 40
AMBIGUOUS_SHARE = 0.5
# filter_health's second finding (PoseFixAid.troubles): more than this share of the match
# attempts made since the first applied one, spaced by the applied matches' travel (at
# least REFUSED_MIN of them), refused by the NIS gate or found on the search window's
# edge (REFUSED_REASONS; derivation in PoseFixAid.refused)
REFUSED_MIN = 20
REFUSED_SHARE = 0.3
REFUSED_REASONS = frozenset({"gated", "edge", "recovered"})
# PoseFixAid.run_note: rings decided, and the share of them skipped as ``prior_better``,
# from which a run without lamps is told it was dead reckoning
PRIOR_BETTER_MIN = 20
PRIOR_BETTER_SHARE = 0.9


def cov_inflation(travel: float, corr_distance: float, cap: float) -> float:
    """Covariance inflation of a match whose error is correlated with the previous
    applied match's (module docstring; Bar-Shalom et al. sec. 8.2).

    Errors with autocorrelation rho^k, rho = exp(-s / L), sampled every s metres of
    travel: their mean carries the information of independent errors of variance
    sum_k rho^|k| = (1 + rho) / (1 - rho) = coth(s / 2L) times theirs.

    Parameters
    ----------
    travel : float
        s, the distance (m) travelled since the previous applied match (inf: none).
    corr_distance : float
        L (m); 0 or less: ``cap`` whatever the travel.
    cap : float
        Upper bound (the robot standing still).

    Returns
    -------
    float
        The factor, in [1, cap].
    """
    if corr_distance <= 0:
        return float(cap)
    x = travel / (2.0 * corr_distance)
    if x <= 0:
        return float(cap)
    return float(np.clip(1.0 / math.tanh(x), 1.0, cap)) if x < 20 else 1.0


def position_sigma_below(cov: np.ndarray, sigma: float) -> bool:
    """Whether the position's largest standard deviation, sqrt(max(lambda_max(P_xy), 0)),
    is below ``sigma``, as ``np.linalg.eigvalsh`` answers it.

    lambda_max of the symmetric 2 x 2 (its lower triangle, as eigvalsh reads it) in
    closed form on Python floats, (a + d) / 2 + sqrt(((a - d) / 2)^2 + b^2): the pose aid
    asks on every ring, and eigvalsh costs 6-10 us of call overhead. The two agree to
    ~1e-16 of the matrix's scale, so the answer is the same unless lambda_max lies
    within 1e-9 of that scale from sigma^2 (or is not finite, or sigma <= 0): eigvalsh
    itself is then asked.

    Parameters
    ----------
    cov : ndarray, shape (3, 3) or (2, 2)
        The pose covariance (its position block is read).
    sigma : float
        The bound (m).

    Returns
    -------
    bool
    """
    a, b, d = float(cov[0, 0]), float(cov[1, 0]), float(cov[1, 1])
    h = 0.5 * (a - d)
    lam = 0.5 * (a + d) + math.sqrt(h * h + b * b)
    bound = sigma * sigma
    margin = 1e-9 * (abs(a) + abs(b) + abs(d) + bound)
    if sigma > 0 and math.isfinite(lam) and abs(lam - bound) > margin:
        return lam < bound
    return bool(np.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]).max(), 0.0)) < sigma)


POSE_FIELDS = (
    "t", "accepted", "reason", "x", "y", "theta", "sxx", "syy", "stt", "degenerate", "nis",
)  # fmt: skip


def moved(a: np.ndarray | None, b: np.ndarray) -> tuple[float, float]:
    """The travel (m) and the turn (rad, absolute) of the dead reckoning from pose ``a``
    to pose ``b`` (both (3,)); infinite without ``a``.

    Parameters
    ----------
    a : ndarray, shape (3,), or None
        The earlier pose.
    b : ndarray, shape (3,)
        The later pose.

    Returns
    -------
    (float, float)
    """
    if a is None:
        return math.inf, math.inf
    return float(np.hypot(b[0] - a[0], b[1] - a[1])), abs(float(wrap_angle(b[2] - a[2])))


@dataclass(frozen=True)
class PoseDecision:
    """One ring's pose fix: the match, and whether the EKF took it (NIS gate)."""

    t: float
    accepted: bool
    reason: str
    pose: np.ndarray
    cov: np.ndarray
    degenerate: int
    nis: float
    innovation: np.ndarray | None = None  # z - h(x) when the EKF was asked (3,)
    odometry: np.ndarray | None = None  # the dead reckoning's pose at the attempt (3,)

    def row(self) -> list[str]:
        """The row of pose_fixes.csv.

        Returns
        -------
        list of str
            t, accepted, reason, x, y, theta, sxx, syy, stt, degenerate, nis.
        """

        def num(v: float) -> str:
            return "" if not np.isfinite(v) else f"{v:.9g}"

        d = np.diag(self.cov)
        vals = [*self.pose, *d]
        return [
            format_time(self.t),
            str(int(self.accepted)),
            self.reason,
            *[num(float(v)) for v in vals],
            str(self.degenerate),
            num(self.nis),
        ]


class PoseFixAid(FlmAhead, FixAid):
    """Plug-in of ``fuzzyslam run``: full-pose fixes update_robot(z, R, idx=[0, 1, 2])."""

    kind = "pose"
    csv_name = "pose_fixes.csv"
    csv_fields = POSE_FIELDS

    def __init__(
        self,
        fgm: BeliefMap,
        params: FixParams,
        flm_source: Callable[[Any, np.ndarray], BeliefMap],
        start_time: float = 0.0,
    ) -> None:
        super().__init__(params, start_time)
        self.matcher = PoseMatcher(fgm, params)
        self.flm_source = flm_source
        self.decisions: list[PoseDecision] = []
        self._count = 0
        self._last_odo: np.ndarray | None = None  # dead-reckoning pose at the last applied match
        # gated matches since the last applied one: (measured pose, covariance, odometry)
        self._gated: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        self.recoveries = 0
        self.wide_searches = 0
        self.near_last = 0  # rings not matched: too near the last applied match
        self.recentred = 0  # searches again centred on an edge peak

    def _can_widen(self) -> bool:
        """Whether the last search was narrower than the widest window."""
        wxy, wth = self.matcher.last_window
        p = self.params
        return wxy < p.pose_window_max or wth < math.radians(p.pose_window_max_deg)

    def _recovery_due(self, m: PoseMatch, odo: np.ndarray) -> bool:
        """Whether the gated match ``m`` and the previous ``pose_recover_after`` - 1 gated
        ones agree on the world-from-odometry transform T_i = pose_i * inv(odo_i)
        (module docstring): each successive pair within the chi-square gate
        (``pose_gate_chi2``, 3 dof) of their summed covariances, in T's frame, and the
        streak spanning at least ``pose_corr_distance`` of travel (closer matches share
        their errors: a door frame matched twice is no second opinion)."""
        self._gated.append((m.pose, m.cov, np.asarray(odo, dtype=float).copy()))
        del self._gated[:-32]
        k, corr = self.params.pose_recover_after, self.params.pose_corr_distance
        # the shortest recent streak of at least k matches spanning corr metres
        last = self._gated[-1][2][:2]
        n = next(
            (
                i
                for i in range(k, len(self._gated) + 1)
                if np.hypot(*(self._gated[-i][2][:2] - last)) >= corr
            ),
            None,
        )
        if n is None:
            return False  # matches that close share their errors: no independent evidence
        streak = self._gated[-n:]
        for (pa, ca, oa), (pb, cb, ob) in itertools.pairwise(streak):
            # the measured pose b predicted from a through the dead reckoning: z_a * (o_a^-1 o_b)
            pred = compose(pa, between(oa, ob))
            d = pb - pred
            d[2] = wrap_angle(d[2])
            if float(d @ np.linalg.solve(ca + cb, d)) > self.params.pose_gate_chi2:
                return False
        return True

    def flm_every_ring(self) -> bool:
        """Every ring is matched (``pose_every`` 1, no ``pose_min_travel`` or
        ``pose_min_turn_deg``: the paper scenario's pose fixes), so the FLM built ahead
        is used (``FlmAhead``).

        Returns
        -------
        bool
            ``pose_every`` is 1 and neither ``pose_min_travel`` nor ``pose_min_turn_deg``
            is set.
        """
        p = self.params
        return p.pose_every == 1 and p.pose_min_travel <= 0.0 and p.pose_min_turn_deg <= 0.0

    def template(self, ring: Any, mounts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What is matched of a ring: its FLM's cells with evidence, as points (N, 2) in
        the robot's frame and their (m(O), m(E)) (N, 2) (``pose_match.flm_evidence``).

        Parameters
        ----------
        ring : Ring
            The ring.
        mounts : ndarray, shape (M, 3)
            The sensors' poses in base_link.

        Returns
        -------
        pts, masses : ndarray, shape (N, 2)
        """
        return flm_evidence(self.flm_source(ring, mounts), self.params.pose_min_mass)

    def on_ring(self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView) -> None:
        """Match the ring's FLM against the FGM around the prediction; apply the match
        (module docstring).

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
        if not self.started(t):
            return
        self._count += 1
        if (self._count - 1) % self.params.pose_every:
            return
        cov = ekf.pose_cov
        if position_sigma_below(cov, self.params.pose_map_sigma):
            # the filter already knows its position better than the map is known: a match
            # would only pull it toward the map's own (correlated) error
            nan3 = np.full(3, np.nan)
            self.decisions.append(
                PoseDecision(t, False, "prior_better", nan3, np.full((3, 3), np.nan), 0, math.nan)
            )
            return
        odo = ekf.odometry_pose
        travel, turn = moved(self._last_odo, odo)
        if not self._apart(travel, turn):
            self.near_last += 1
            return  # too close to the last applied match to add information (params)
        scale = cov_inflation(travel, self.params.pose_corr_distance, self.params.pose_cov_scale)
        tmpl = self.template(ring, mounts)
        m = self.matcher.match_points(*tmpl, ekf.pose, cov, scale)
        recover = self.params.pose_recover_after > 0
        if recover and m.reason == "edge":
            # the mode on the window's edge: first a search of the same size centred on
            # the lattice's best pose (a hill-climbing step, as cheap as the first)
            m = self.matcher.match_points(*tmpl, self.matcher.last_peak, cov, scale)
            self.recentred += 1
        widen = 1.0
        while recover and m.reason in ("edge", "no_match") and self._can_widen():
            # the mode lies on or beyond the window: search again 3 times wider
            widen *= 3.0
            m = self.matcher.match_points(*tmpl, ekf.pose, cov, scale, widen=widen)
            self.wide_searches += 1
        odo = np.array(odo, dtype=float)
        if not m.ok:
            self.decisions.append(
                PoseDecision(t, False, m.reason, m.pose, m.cov, m.degenerate, math.nan, None, odo)
            )
            return
        res = ekf.update_robot(m.pose, m.cov, [0, 1, 2], gate_chi2=self.params.pose_gate_chi2)
        reason = "ok" if res.accepted else "gated"
        if res.accepted:
            self._gated.clear()
        elif recover and self._recovery_due(m, odo):
            # the last pose_recover_after gated matches agree on the correction of the
            # dead reckoning: the filter is wrong, not the matches (module docstring)
            v = np.asarray(res.innovation, dtype=float).reshape(3)
            ekf.inflate_robot(np.diag(v * v))
            res = ekf.update_robot(m.pose, m.cov, [0, 1, 2], gate_chi2=None)
            reason = "recovered"
            self.recoveries += 1
            self._gated.clear()
        if res.accepted:
            self._last_odo = np.array(odo, dtype=float)
        v = np.asarray(res.innovation, dtype=float).reshape(-1)
        self.decisions.append(
            PoseDecision(
                t, bool(res.accepted), reason, m.pose, m.cov, m.degenerate, float(res.nis), v, odo
            )
        )

    def update_rows(self) -> list[dict[str, Any]]:
        """The EKF update attempts, as rows of run's updates.csv (docs/contracts.md sec. 2).

        Returns
        -------
        list of dict
            t, kind, id, dof, nis, accepted, v0, v1, v2 of each match the filter was asked about.
        """
        return [
            {
                "t": d.t,
                "kind": self.kind,
                "id": -1,
                "dof": 3,
                "nis": d.nis,
                "accepted": int(d.accepted),
                "v0": d.innovation[0],
                "v1": d.innovation[1],
                "v2": d.innovation[2],
            }
            for d in self.decisions
            if d.innovation is not None
        ]

    def trouble(self) -> tuple[str, float] | None:
        """The aid's finding for the run's ``filter_health`` (slam/run_results.py):
        ("pose_matches_ambiguous", the time) once more than ``AMBIGUOUS_SHARE`` of
        ``AMBIGUOUS_WINDOW`` successive match attempts were ``flat`` or ``multimodal``,
        else None.

        A ring that constrains the pose gives a single peaked likelihood; when most rings
        give a flat or many-peaked one, the range sensor cannot tell the pose apart in
        this map (too few sensors: a ring of three sonars; a featureless or repetitive
        place), and the few matches that are applied are the ones aliasing made look
        peaked: the filter can follow them away, confidently (their NIS stays small
        because they are searched around its own prediction). Measured: at most 15 % in
        any window on the simulated and real logs whose runs stay localised, 90 % with a
        3-sonar ring that got lost.

        Returns
        -------
        (str, float) or None
        """
        tried = [d for d in self.decisions if d.reason != "prior_better"]
        w = AMBIGUOUS_WINDOW
        if len(tried) < w:
            return None
        bad = np.cumsum([d.reason in ("flat", "multimodal") for d in tried])
        counts = bad[w - 1 :] - np.concatenate(([0], bad[:-w]))
        over = np.flatnonzero(counts > AMBIGUOUS_SHARE * w)
        if over.size == 0:
            return None
        return "pose_matches_ambiguous", tried[int(over[0]) + w - 1].t

    def refused(self) -> tuple[str, float] | None:
        """("pose_matches_refused", the time) once more than ``REFUSED_SHARE`` of the match
        attempts made since the first match applied (``ok``), spaced by the travel of
        the applied ones (:meth:`_spaced`), and at least ``REFUSED_MIN`` of them, were
        refused by the NIS gate or found on the search
        window's edge (``gated``, ``edge``, and ``recovered``: gated first), else None.
        Rings the filter knew better than the map (``prior_better``) are not attempts.
        A run with no match applied is judged from its first attempt.

        Warm-up. The attempts before the first applied match are the start-up transient:
        a start pose off by some degrees has its first matches refused until the filter's
        covariance has grown to take one, and counted from the run's start the share is
        most sensitive while there are fewest attempts (the Freiburg excerpt started
        10 deg off: 6 refused before its first applied match, 12 of the first 20
        attempts, flagged at 15.7 s though its position error stays 0.114 m against the
        truth start's 0.108 m; since its first applied match, at most 30 %).

        Derivation. A consistent filter's match is refused by the 3-dof gate at 99 %
        (``pose_gate_chi2`` 11.34) 1 % of the time, and its mode lies outside the
        +-3 sigma search window at most 3 x 0.27 %: about 2 % of attempts. The attempts
        counted are spaced as the applied matches are (:meth:`_spaced`: a refused ring
        retried at the next ring, a few centimetres on, sees the same walls and is not
        a new trial), so they are nearly independent trials, and more than 30 % of at
        least 20 refused is far beyond that rate: by chance, at a refusal rate of 5 %
        (2.5 times the consistent one: map errors) less than 3e-4 over a run of 2000
        counted attempts (the binomial tails summed over n, a union bound), at 10 %
        less than 3e-2. Such a filter's own pose is the outlier, not the matches (an
        odometry scale or wheel base error, a range sensor mount turned, ranges stamped
        off the odometry's clock).

        Over the attempts since the warm-up, not a sliding window: a localised run can
        go through a stretch of refusals and recover (the full Freiburg sonar log: 40
        refusals in a row, 35 s at 0.5 m of error, then localised again). Measured on
        the CARMEN logs with ``--fix-from 0``, since the first applied match, spaced:
        at most 7 % on the full ACES and Freiburg logs (scan and sonar), 10-15 % on a
        synthetic 40-min building's 9-sonar ring (counted ring by ring it reached 74 %
        at 19 s, entering a room, with the run's error below 0.23 m throughout);
        Freiburg with its odometry scaled 15 %: 40 % with the laser, flagged at 41 s
        (counted ring by ring: at 20 s; its error passes 1 m at 20 s, and the NIS
        windows flag it at 90 s), 23 % with the sonars (flagged by its NIS windows at
        98 s); the Freiburg excerpt with its laser's mount turned 10 deg: flagged. A
        filter that goes wrong late in a long log is found only once its refusals
        outnumber the share of the matches it took before (the NIS windows may see it
        first).

        Returns
        -------
        (str, float) or None
        """
        tried = [d for d in self.decisions if d.reason != "prior_better"]
        # the start-up transient (a start pose off by 10 deg: its first attempts refused
        # while the filter settles) is not counted: from the first match applied as "ok"
        first = next((k for k, d in enumerate(tried) if d.reason == "ok"), 0)
        tried = self._spaced(tried[first:])
        if len(tried) < REFUSED_MIN:
            return None
        bad = np.cumsum([d.reason in REFUSED_REASONS for d in tried])
        n = np.arange(1, len(tried) + 1)
        over = np.flatnonzero((bad > REFUSED_SHARE * n) & (n >= REFUSED_MIN))
        if over.size == 0:
            return None
        return "pose_matches_refused", tried[int(over[0])].t

    def _apart(self, travel: float, turn: float) -> bool:
        """Whether the dead reckoning has moved ``pose_min_travel`` or turned
        ``pose_min_turn_deg`` (``travel`` m, ``turn`` rad: :func:`moved`)."""
        p = self.params
        return travel >= p.pose_min_travel or turn >= math.radians(p.pose_min_turn_deg)

    def _spaced(self, tried: list[PoseDecision]) -> list[PoseDecision]:
        """The attempts :meth:`refused` counts: every applied one, and a refused one only
        once the dead reckoning has moved ``pose_min_travel`` or turned
        ``pose_min_turn_deg`` since the last attempt counted. An applied match waits
        that long for the next; a refused ring is retried at the next ring, a few
        centimetres on, where the same walls give the same answer: counted each, a
        localised run's stretch of refusals outweighed its matches by the ring rate
        over the travel (a synthetic building's 9 sonars at 5 Hz entering a room 16 s
        into a 40-min log: 6 applied, then 20 refused over 3 m, flagged at 19 s; its
        error never above 0.23 m). Attempts without their dead reckoning (made by hand)
        all count.

        Parameters
        ----------
        tried : list of PoseDecision
            The attempts, in time order.

        Returns
        -------
        list of PoseDecision
        """
        out: list[PoseDecision] = []
        last: np.ndarray | None = None
        for d in tried:
            odo = d.odometry
            if d.accepted or odo is None or self._apart(*moved(last, odo)):
                out.append(d)
                last = odo
        return out

    def troubles(self) -> list[tuple[str, float]]:
        """Every finding of the aid for ``filter_health``: :meth:`trouble`'s (matches
        ambiguous) and :meth:`refused`'s (matches refused), in time order.

        Returns
        -------
        list of (str, float)
        """
        found = [f for f in (self.trouble(), self.refused()) if f is not None]
        return sorted(found, key=lambda f: f[1])

    def run_note(self, lamps: bool) -> str:
        """One line for stderr when more than ``PRIOR_BETTER_SHARE`` of the rings decided
        (at least ``PRIOR_BETTER_MIN``) were skipped as ``prior_better`` in a run without
        lamps, else ''. Such a ring is not matched because the filter's position sigma is
        below ``fixes.pose_map_sigma``; with no lamps, that is the pose fixes' own
        covariance floor (``pose_min_sigma``) or ``pose_map_sigma`` set far too large
        (10 times on the Freiburg excerpt: 271 of 274 rings skipped, the run dead
        reckoning with nothing said). With lamps the filter may know its position that
        well from them: nothing is said.

        Parameters
        ----------
        lamps : bool
            Whether the run's log has lamps (``LogInputs.lamp_source`` not "none").

        Returns
        -------
        str
        """
        n = len(self.decisions)
        skipped = sum(d.reason == "prior_better" for d in self.decisions)
        if lamps or n < PRIOR_BETTER_MIN or skipped <= PRIOR_BETTER_SHARE * n:
            return ""
        p = self.params
        return (
            f"pose fixes: {skipped} of {n} rings not matched, the filter's position sigma "
            f"already below fixes.pose_map_sigma ({p.pose_map_sigma:g} m; the summary's "
            "aids.PoseFixAid.reasons.prior_better): with no lamps the estimate is nearly "
            f"dead reckoning: are fixes.pose_map_sigma and pose_min_sigma "
            f"({p.pose_min_sigma:g} m) larger than the map's error?"
        )

    def summary(self) -> PoseSummary:
        """The aid's entry in the run summary.

        Returns
        -------
        PoseSummary
            rings, before_start, accepted, reasons, degenerate, mean_nis, recoveries,
            wide_searches, near_last_match, recentred_searches.
        """
        reasons = Counter(d.reason for d in self.decisions)
        acc = [d for d in self.decisions if d.accepted]
        return PoseSummary(
            rings=len(self.decisions),
            before_start=self.before_start,
            accepted=len(acc),
            reasons=dict(sorted(reasons.items())),
            degenerate=int(sum(d.degenerate > 0 for d in acc)),
            mean_nis=float(np.mean([d.nis for d in acc])) if acc else None,
            recoveries=self.recoveries,
            wide_searches=self.wide_searches,
            near_last_match=self.near_last,
            recentred_searches=self.recentred,
        )

    def messages(self, topics: Any, start: float | None = None) -> list:
        """The pose matches for estimates.mcap (``topics.pose_fixes``, fixes/viewer.py),
        and the map (``viewer_map``, stamped ``start``) when this aid shows it.

        Parameters
        ----------
        topics : Topics
            The config's topics (the aid's own and the map's).
        start : float or None
            The log's start (the map's stamp); None: no map.

        Returns
        -------
        list of (str, str, message, float)
        """
        from fuzzyslam.fixes.viewer import map_messages, pose_fix_messages

        fixes = pose_fix_messages(self.decisions, topics.pose_fixes)
        return map_messages(self.viewer_map, topics, start) + fixes
