"""The EKF-SLAM loop over time-ordered events (pure core: no file I/O).

Events (built from a log by :mod:`fuzzyslam.slam.inputs`, or by a test; the data types
are in :mod:`fuzzyslam.slam.events`):

- :class:`Odom`: an odometry increment (d_trans, d_rot) ending at time t -> prediction;
- :class:`Frame`: lamp detections z (m, 2) in base_link with covariances (m, 2, 2)
  -> association (JCBB), joint lamp update, tentative lamps, new lamps;
- :class:`RingEvent`: a sonar ring -> handed to every aid (heading/pose fixes) whose
  ``start_time`` has come.

Aids follow the protocol :class:`Aid`. The rows that grow with the log (trajectory and
covariance, odometry increments, update attempts, landmark snapshots) go to a
:class:`RowSink` as they are final: by default a :class:`MemorySink` (the result then
holds the trajectory, its covariance, the dead reckoning of the same increments and one
row per measurement update attempt), or a streaming sink that writes them to files
(``fuzzyslam.slam.outputs.StreamingOutputs``), so memory stays flat over long logs.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from fuzzyslam.slam import calibration as cal
from fuzzyslam.slam import calibration_files
from fuzzyslam.slam.association import TentativeLamps
from fuzzyslam.slam.ekf import EkfSlam, Preintegrator, lamp_init
from fuzzyslam.slam.events import (
    Aid,
    Event,
    Frame,
    LampRecord,
    MemorySink,
    Odom,
    RingEvent,
    RowSink,
    SlamResult,
    UpdateRow,
)
from fuzzyslam.slam.health import DivergenceMonitor
from fuzzyslam.slam.lamp_update import associate_update
from fuzzyslam.slam.map_motion import MapMotionMonitor
from fuzzyslam.slam.noise import DetectionNoiseEstimator
from fuzzyslam.slam.params import SlamParams
from fuzzyslam.slam.relocalise import Relocaliser
from fuzzyslam.slam.run_results import LateEvents, RunCounts, slam_result
from fuzzyslam.slam.start_anchor import StartAnchor
from fuzzyslam.streams.sonar import ring_mounts

CALIB_PERIOD_S = 1.0  # calibration.csv: a row at most this often (s)
# the upper triangle of the pose covariance, row by row (a trajectory row's covariance)
_COV_ROWS, _COV_COLS = np.triu_indices(3)

# the loop's data (slam/events.py), importable from here as before
__all__ = [
    "Aid",
    "Event",
    "Frame",
    "LampRecord",
    "MemorySink",
    "Odom",
    "RingEvent",
    "RowSink",
    "SlamResult",
    "SlamRunner",
    "UpdateRow",
]


@dataclass
class SlamRunner:
    """Run EKF-SLAM over events (module docstring)."""

    params: SlamParams
    start_pose: np.ndarray
    aids: list = field(default_factory=list)
    mounts: np.ndarray | None = None
    snapshot_period: float | None = None  # default: params.landmarks_period
    sink: RowSink | None = None  # default: a MemorySink
    # odometry self-calibration (slam/calibration.py): None, or the model and its prior
    calibration: cal.Calibration | None = None
    # collect the innovations for the detection noise estimate (slam/noise.py): off, the
    # runner's ``noise`` is None (the run stage's frames, whose summary has no estimate)
    estimate_noise: bool = True

    def __post_init__(self) -> None:
        p = self.params
        if self.snapshot_period is None:
            self.snapshot_period = p.landmarks_period
        self.start_pose = np.asarray(self.start_pose, dtype=float)
        cm = self.calibration
        self.ekf = EkfSlam(
            self.start_pose,
            np.diag(np.square(p.start_sigma)),
            p.odometry_noise,
            calib=None if cm is None else cm.factors,
            calib_cov=None if cm is None else cm.cov,
            first_estimates=p.first_estimates,
        )
        if cm is None:
            self.preint = Preintegrator(p.odometry_noise)
        else:
            self.preint = cal.CalibratedPreintegrator(p.odometry_noise, cm)
            self.ekf.heading_frozen = cal.HEADING_FROZEN[cm.kind]
        # calibration.csv rows (t, factors, sigmas, correlations), one per CALIB_PERIOD_S
        self.calib_rows: list[list[str]] = []
        self._last_calib = -np.inf
        self.health = DivergenceMonitor()  # NIS and association-rate windows (health.py)
        # the detection noise the innovations imply
        self.noise = DetectionNoiseEstimator() if self.estimate_noise else None
        self.tentative = TentativeLamps(
            p.tentative_hits, p.tentative_radius, p.tentative_timeout, p.gate_chi2
        )
        self.counts: dict[str, int] = dict.fromkeys(
            "odometry frames detections associated lamps_created lamps_deferred "
            "duplicates_guarded ambiguous frames_stale_odometry rings aid_calls "
            "out_of_order".split(),
            0,
        )
        self.relocaliser = Relocaliser.from_params(p)
        self.anchor = StartAnchor()  # the map's first lamps at first sight (start_anchor.py)
        self.map_motion = MapMotionMonitor()
        self.late = LateEvents()  # events skipped as older than the filter's time
        if self.sink is None:
            self.sink = MemorySink()
        # the last trajectory row is held back until the next one: a row of the same
        # time replaces it (e.g. odometry then a frame at one stamp)
        self._pending: tuple[float, np.ndarray, np.ndarray] | None = None
        self._n_rows = 0  # rows recorded (the pending one included)
        self._first_seen: list[float] = []
        self._last_seen: list[float] = []
        self._obs: list[int] = []
        self._last_t = -np.inf
        self._last_odometry = -np.inf  # time of the last odometry increment
        self._last_record = -np.inf
        self._last_snapshot = -np.inf

    @property
    def last_time(self) -> float:
        """Time (s) of the last event handled."""
        return self._last_t

    @property
    def updates(self) -> list[UpdateRow]:
        """The update attempts so far (a :class:`MemorySink` only)."""
        return self.sink.updates  # type: ignore[union-attr]

    def _update(self, row: UpdateRow) -> None:
        self.sink.update(row)  # type: ignore[union-attr]

    # -- steps ----------------------------------------------------------------------------

    def _record(self, t: float) -> None:
        """Record the current pose and covariance (replacing a row of the same time)."""
        self.flush()
        row = self.ekf.P[_COV_ROWS, _COV_COLS]  # pxx pxy pxt pyy pyt ptt (covariance.csv)
        pending = self._pending
        if pending is None or pending[0] != t:
            if pending is not None:
                self.sink.row(*pending)  # type: ignore[union-attr]
            self._n_rows += 1
        self._pending = (t, self.ekf.pose, row)
        self._last_record = t
        if self.calibration is not None and t - self._last_calib >= CALIB_PERIOD_S:
            self.calib_rows.append(calibration_files.csv_row(t, self.ekf.calib, self.ekf.calib_cov))
            self._last_calib = t
        if self._n_rows % 50 == 0:
            self.ekf.check_covariance()  # O(n^3), every 50 rows (health.repair_covariance)
        if t - self._last_snapshot >= self.snapshot_period:
            self._snapshot(t)

    def _snapshot(self, t: float) -> None:
        self.sink.snapshot(t, self.ekf.lamps.copy(), self.ekf.lamp_covs())  # type: ignore[union-attr]
        self._last_snapshot = t

    def flush(self) -> None:
        """Apply the odometry preintegrated since the last flush (one O(n) prediction)."""
        pre = self.preint
        if not pre.steps:
            return
        if self.relocaliser is not None:
            self.relocaliser.moved(pre.delta)
        self.predict()

    def predict(self) -> None:
        """Apply the preintegrated odometry to the filter (:meth:`flush`'s prediction)."""
        pre, cm = self.preint, self.calibration
        if cm is None:
            self.ekf.predict_relative(pre.delta, pre.q)
            pre.reset()
            return
        # x' = x (+) delta(c), D = d delta / dc; then the factors' random walk
        self.ekf.predict_relative(pre.delta, pre.q_calib(self.ekf.calib_cov), pre.d_calib)
        cal.diffuse(self.ekf, cm.var_per_m * pre.dist + cm.var_per_rad * pre.turn)
        pre.reset(self.ekf.calib)

    def odometry(self, ev: Odom) -> None:
        """Odometry increment: preintegrated (applied at the next flush), and dead reckoning.

        Parameters
        ----------
        ev : Odom
            The increment (d_trans m, d_rot rad) ending at ``ev.t`` (s).
        """
        self._last_odometry = ev.t
        if self.calibration is not None and not self.preint.steps:
            self.preint.reset(self.ekf.calib)  # the factors as the last update left them
        self.preint.add(ev.d_trans, ev.d_rot)
        self.anchor.odometry(ev.d_trans, ev.d_rot)
        self.sink.odometry(ev.t, ev.d_trans, ev.d_rot)  # type: ignore[union-attr]
        self.counts["odometry"] += 1
        if ev.t - self._last_record >= self.params.record_period:
            self._record(ev.t)

    def frame(self, ev: Frame) -> None:
        """Associate the frame's detections, update, then manage new lamps.

        A detection takes part in at most one of: an update (paired by JCBB), nothing
        (ambiguous: another hypothesis fits nearly as well, ``slam.ambiguity_margin``),
        a rejected attempt (near a mapped lamp that no other detection of the frame
        explains: the duplicate guard), or a tentative lamp.

        Parameters
        ----------
        ev : Frame
            The frame at ``ev.t`` (s): detections ``z`` (m, 2) in base_link (m) with their
            covariances ``cov`` (m, 2, 2).
        """
        ekf = self.ekf
        self.flush()
        self.counts["frames"] += 1
        if -np.inf < self._last_odometry < ev.t - self.params.odometry_stale_s:
            # the odometry has been silent: the robot may have moved since the pose the
            # detections would be compared with, so they could only be misassociated
            # (duplicates). The motion itself is not lost (cumulative odometry).
            self.counts["frames_stale_odometry"] += 1
            if self.late.stale_at is None:
                self.late.stale_at = ev.t
            self._record(ev.t)
            return
        z = np.asarray(ev.z, dtype=float).reshape(-1, 2)
        r = np.asarray(ev.cov, dtype=float).reshape(-1, 2, 2)
        m = len(z)
        self.counts["detections"] += m
        self.tentative.expire(ev.t)
        self.anchor.frame(ekf, self.preint, ev.t, z, r)
        if m:
            d2 = ekf.individual_compatibility(z, r)
            rel, p = self.relocaliser, self.params
            # a frame the relocalisation test would not test is updated at once; else the
            # test (a pose that has left its covariance?) gives JCBB's association when it
            # made it, and the iterate when it relocalised (the update is linearised there)
            done = rel.update_if_explained(ekf, z, r, d2) if rel is not None else None
            if done is None:
                known, lin = None, None
                if rel is not None:
                    d2, known, lin = rel(ekf, z, r, d2, ev.t)
                with ekf.linearised_at(lin):  # the iterated EKF's update (relocalise.py)
                    done = associate_update(ekf, z, r, d2, p.gate_chi2, p.ambiguity_margin, known)
            assoc, res = done
            if rel is not None:  # its window keeps what the map left unexplained
                rel.unexplained(ev.t, z, r, assoc)
            pairs = assoc.pairs
            if pairs and self.calibration is not None:
                self.preint.mark()  # an update: the calibration Jacobian's next instrument
            if pairs:
                for a, (j, i) in enumerate(pairs):
                    self._update(
                        UpdateRow(
                            ev.t,
                            "lamp",
                            i,
                            2,
                            float(d2[j, i]),
                            True,
                            res.innovation[2 * a : 2 * a + 2],
                        )
                    )
                    self._last_seen[i] = ev.t
                    self._obs[i] += 1
                if self.noise is not None:
                    det = [j for j, _ in pairs]
                    self.noise.add_joint(z[det], res.innovation, res.s, r[det])
                self.counts["associated"] += len(pairs)
                for j, i in pairs:
                    self.health.observe(ev.t, float(d2[j, i]), 2)
            self.counts["ambiguous"] += len(assoc.ambiguous)
            if m and ekf.n_lamps:
                explained = len(pairs) + len(assoc.ambiguous)
                if rel is not None and rel.explained_before is not None:  # relocalised: what
                    explained = rel.explained_before  # the filter explained as it stood
                self.health.observe_frame(ev.t, m, explained)
            used = {j for j, _ in pairs} | set(assoc.ambiguous)
            rest = [j for j in range(m) if j not in used]
            if rest and any(getattr(a, "pose_suspect", False) for a in self.aids):
                # an aid finds the pose inconsistent with the map (e.g. an unseen bump):
                # a lamp initialised from it would be a duplicate; wait
                self.counts["lamps_deferred"] += len(rest)
            elif rest:
                taken = {i for _, i in pairs}
                self._new_lamps(ev.t, z[rest], r[rest], d2[rest], taken)
        self._record(ev.t)
        if self.map_motion.due(ev.t):  # the map moving beyond its covariance?
            self.map_motion.observe(ev.t, ekf.lamps, ekf.lamp_covs())

    def _new_lamps(
        self, t: float, z: np.ndarray, r: np.ndarray, d2_before: np.ndarray, taken: set[int]
    ) -> None:
        """Unpaired detections: guard against duplicates, then tentative lamps.

        The guard refuses a detection within ``new_lamp_chi2`` (squared Mahalanobis) of
        a mapped lamp, except of lamps that another detection of the same frame explains
        (``taken``): one frame does not see one landmark twice (mutual exclusion), so a
        second detection there is a second landmark, however close.
        """
        ekf = self.ekf
        d2 = ekf.individual_compatibility(z, r)
        if taken and d2.shape[1]:
            d2[:, sorted(taken)] = np.inf
        pose, prr = ekf.pose, ekf.pose_cov
        tentative_taken: set[int] = set()
        for j in range(len(z)):
            if d2.shape[1]:
                i = int(np.argmin(d2[j]))
                if d2[j, i] <= self.params.new_lamp_chi2:
                    # near a mapped lamp but not paired with it: a rejected update attempt
                    self._update(
                        UpdateRow(
                            t, "lamp", i, 2, float(d2_before[j, i]), False, np.full(2, np.nan)
                        )
                    )
                    self.counts["duplicates_guarded"] += 1
                    continue
            world, jr, jz = lamp_init(pose, z[j])
            cov = jr @ prr @ jr.T + jz @ r[j] @ jz.T
            if self.tentative.observe(t, world, tentative_taken, cov):
                self.anchor.confirmed.append((j, world))
        for _ in range(self.anchor.give_birth(self, z, r)):  # ekf.add_lamp (start_anchor.py)
            self.health.observe_birth(t, prr)
            self._first_seen.append(t)
            self._last_seen.append(t)
            self._obs.append(1)
            self.counts["lamps_created"] += 1

    def ring(self, ev: RingEvent) -> None:
        """Hand a sonar ring to every aid whose start time has come; their robot updates
        become update rows.

        Parameters
        ----------
        ev : RingEvent
            The ring at ``ev.t`` (s): ``ev.ring`` (ranges (M,), max ranges (M,), fov);
            ``ev.ahead``: what each aid computed from it ahead (``take_ahead``), or None.
        """
        self.counts["rings"] += 1
        self.flush()
        ahead = ev.ahead
        for k, aid in enumerate(self.aids):
            if ev.t >= aid.start_time:
                if ahead is not None and ahead[k] is not None:  # computed in slam/prefetch.py
                    aid.take_ahead(ev.ring, ahead[k])
                aid.on_ring(ev.t, ev.ring, ring_mounts(ev.ring, self.mounts), self.ekf)
                self.counts["aid_calls"] += 1
        for idx, res in self.ekf.robot_updates:
            self.anchor.updated(res.accepted)  # the rewind would not be exact
            if res.accepted and self.calibration is not None:
                self.preint.mark()
            kind = "heading" if idx == (2,) else "pose"
            self._update(UpdateRow(ev.t, kind, -1, len(idx), res.nis, res.accepted, res.innovation))
            self.health.observe(ev.t, res.nis, len(idx))
        self.ekf.robot_updates.clear()

    # -- loop -----------------------------------------------------------------------------

    def run(
        self,
        events: Iterable[Event],
        progress: Callable[[float], None] | None = None,
        t0: float | None = None,
    ) -> SlamResult:
        """Process events in time order; an event older than the last one is counted, skipped.

        Parameters
        ----------
        events : iterable of Odom, Frame or RingEvent
            The events, in time order.
        progress : callable or None
            ``progress(t)`` after each event (s).
        t0 : float or None
            Time of the start pose (s); default: the first event's.

        Returns
        -------
        SlamResult
            :meth:`result`.
        """
        first = self._n_rows == 0
        if first and t0 is not None:
            self._start(float(t0))
            first = False
        for ev in events:
            if first:
                self._start(ev.t)
                first = False
            if ev.t < self._last_t:
                self.counts["out_of_order"] += 1
                self.late.add(ev, self._last_t)
                continue
            self._last_t = ev.t
            if isinstance(ev, Odom):
                self.odometry(ev)
            elif isinstance(ev, Frame):
                self.frame(ev)
            else:
                self.ring(ev)
            if progress is not None:
                progress(ev.t)
        return self.result()

    def _start(self, t: float) -> None:
        """The start pose: first dead-reckoning time and first trajectory row."""
        self.sink.odometry_start(t)  # type: ignore[union-attr]
        self._record(t)

    def result(self) -> SlamResult:
        """Finish the run (last row and snapshot to the sink) and return its result.

        Returns
        -------
        SlamResult
            Trajectory (N, 3) with covariance rows (N, 6), dead reckoning (K, 3), lamps,
            update rows, :class:`~fuzzyslam.slam.run_results.RunCounts`, snapshots, the
            filter (only the last row when streamed: ``run_results.slam_result``).
        """
        self.flush()
        ekf = self.ekf
        if self._pending is not None and self._last_t > self._pending[0]:
            self._record(self._last_t)
        if self._last_t > -np.inf:
            self._snapshot(self._last_t)
        last = self._pending
        if last is not None:
            self.sink.row(*last)  # type: ignore[union-attr]
            self._pending = None
        covs = ekf.lamp_covs()
        lamps = [
            LampRecord(
                i,
                float(ekf.lamps[i, 0]),
                float(ekf.lamps[i, 1]),
                covs[i],
                self._first_seen[i],
                self._last_seen[i],
                self._obs[i],
            )
            for i in range(ekf.n_lamps)
        ]
        counts = RunCounts(
            **self.counts,
            tentative_expired=self.tentative.expired,
            tentative_pending=len(self.tentative.items),
            **(self.relocaliser.counts() if self.relocaliser is not None else {}),
        )
        return slam_result(self.sink, self.start_pose, last, lamps, counts, ekf)
