"""The map's first lamps born where they were first seen: at the start pose [ours].

The map's frame is the start pose's (``slam.start_pose``, ``start_sigma``): the only
absolute information a SLAM run has. A lamp becomes a landmark only after
``tentative_hits`` consistent sightings (slam/association.py ``TentativeLamps``), and was
born from the pose of the sighting that confirmed it; for the map's first lamps that pose
is the start pose plus the odometry of the confirmation delay (0.4 s at 5 frames/s and 3
hits), whose heading error nothing else observes. The whole map then inherits it as a
rotation about the start: on the paper scenario the filter's heading error when the
first lamps were born was -2.5, 4.2, -0.7, 0.3 and 3.9 mrad on seeds 0-4, the
dead-reckoning heading error of those 0.4 s (7.9 mrad/sqrt(m) of encoder noise, 12 cm),
and phase A's mean position error 1.48, 2.44, 0.74, 0.24 and 2.22 cm, in that order.

While the map is empty and the filter has made no update, its state is the start pose
(and the calibration factors) propagated by odometry alone, so it can be rewound exactly:
:class:`StartAnchor` keeps the filter's state and preintegrator at the first frame with
detections, and the odometry increments since. When the first lamps are confirmed, the
runner restores that state, gives birth to the confirmed lamps from their sightings in
that frame (``EkfSlam.add_lamp``: the standard initialisation, lamp and pose correlated)
and replays the odometry (the same prediction, composed): the filter is then the one that
had made those lamps landmarks at their first sighting, with their 3-hit confirmation
still required. The confirming frame's own sightings are not applied as updates (the
next frame's are). An update before the first birth (a heading fix from t = 0) drops
the snapshot, which would no longer rewind exactly; the next frame with detections takes
a new one. Every lamp is born through :meth:`StartAnchor.give_birth`; later ones (no
snapshot) from their confirming sighting, as before.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from fuzzyslam.slam.calibration import CalibratedPreintegrator
from fuzzyslam.slam.ekf import EkfSlam, lamp_init


@dataclass
class Snapshot:
    """The filter at the first frame with detections, while the map is empty.

    Parameters
    ----------
    t : float
        The frame's time (s).
    x : ndarray, shape (m0,)
        The state (pose and calibration factors).
    p : ndarray, shape (m0, m0)
        Its covariance.
    odometry_pose : ndarray, shape (3,)
        The filter's dead reckoning.
    preint : Preintegrator
        A copy of the runner's preintegrator (flushed; its calibration instrument included).
    z : ndarray, shape (m, 2)
        The frame's detections (robot frame).
    r : ndarray, shape (m, 2, 2)
        Their covariances.
    world : ndarray, shape (m, 2)
        The detections placed from the frame's pose (world frame).
    increments : list of (float, float)
        The odometry increments (d_trans, d_rot) since the frame.
    """

    t: float
    x: np.ndarray
    p: np.ndarray
    odometry_pose: np.ndarray
    preint: object
    z: np.ndarray
    r: np.ndarray
    world: np.ndarray
    increments: list[tuple[float, float]] = field(default_factory=list)

    def restore(self, ekf: EkfSlam):
        """Put ``ekf`` (no lamps) back as it was, and return the preintegrator of the
        odometry since then (to be applied by the runner's ``predict``).

        Parameters
        ----------
        ekf : EkfSlam
            The filter (updated in place).

        Returns
        -------
        Preintegrator
        """
        ekf.x[:] = self.x
        ekf.P[:, :] = self.p
        ekf.odometry_pose = self.odometry_pose.copy()
        ekf.restart_linearisation()  # no update since: the last prediction's position
        pre = copy.deepcopy(self.preint)
        if isinstance(pre, CalibratedPreintegrator):
            pre.reset(ekf.calib)  # the factors as the anchor had them (no update since)
        for inc in self.increments:
            pre.add(*inc)
        return pre


@dataclass
class StartAnchor:
    """The lamps confirmed in a frame, born as landmarks (:meth:`give_birth`), the map's
    first ones at their first sighting (module docstring): :meth:`frame` and
    :meth:`odometry` keep the snapshot while the map is empty, :meth:`updated` drops it
    at an update (the next frame with detections takes a new one). A snapshot older than
    ``horizon`` seconds is replaced by the next frame's."""

    horizon: float = 6.0
    snapshot: Snapshot | None = None
    # the lamps confirmed in the current frame: (detection index, world position)
    confirmed: list[tuple[int, np.ndarray]] = field(default_factory=list)

    def frame(self, ekf: EkfSlam, preint, t: float, z: np.ndarray, r: np.ndarray) -> None:
        """A frame: the snapshot, if it has detections, the map is empty and there is none.

        Parameters
        ----------
        ekf : EkfSlam
            The filter (flushed).
        preint : Preintegrator
            The runner's preintegrator (no pending step).
        t : float
            The frame's time (s).
        z : ndarray, shape (m, 2)
            The frame's detections.
        r : ndarray, shape (m, 2, 2)
            Their covariances.
        """
        if self.snapshot is not None and t - self.snapshot.t > self.horizon:
            self.snapshot = None
        if self.snapshot is not None or not len(z) or ekf.n_lamps:
            return
        pose = ekf.pose
        world = np.array([lamp_init(pose, zj)[0] for zj in z]).reshape(-1, 2)
        self.snapshot = Snapshot(
            t, ekf.x.copy(), ekf.P.copy(), ekf.odometry_pose.copy(), copy.deepcopy(preint),
            np.array(z, dtype=float).reshape(-1, 2), np.array(r, dtype=float).reshape(-1, 2, 2),
            world,
        )  # fmt: skip

    def odometry(self, d_trans: float, d_rot: float) -> None:
        """An odometry increment (kept while the snapshot stands).

        Parameters
        ----------
        d_trans, d_rot : float
            The increment (m, rad).
        """
        if self.snapshot is not None:
            self.snapshot.increments.append((d_trans, d_rot))

    def updated(self, accepted: bool) -> None:
        """An update of the filter (``accepted``): the snapshot no longer rewinds exactly.

        Parameters
        ----------
        accepted : bool
            Whether the update changed the filter.
        """
        if accepted:
            self.snapshot = None

    def give_birth(self, runner, z: np.ndarray, r: np.ndarray) -> int:
        """Make the lamps ``confirmed`` in this frame landmarks (``runner.ekf.add_lamp``).

        With a snapshot (the map's first lamps), each is born from the snapshot frame's
        nearest detection within the tentative radius (one lamp per detection), on the
        filter rewound to the snapshot, and the odometry since is replayed
        (``runner.predict``); the others, and all without a snapshot, from this frame's
        detections ``z``, ``r``.

        Parameters
        ----------
        runner : SlamRunner
            Its ``ekf``, ``preint``, ``params.tentative_radius`` and ``predict``.
        z : ndarray, shape (m, 2)
            This frame's detections.
        r : ndarray, shape (m, 2, 2)
            Their covariances.

        Returns
        -------
        int
            The lamps born.
        """
        held, snap, ekf = self.confirmed, self.snapshot, runner.ekf
        if not held:
            return 0
        self.confirmed = []
        first = [-1] * len(held)
        if snap is not None:
            self.snapshot = None
            taken: list[int] = []
            for a, (_, w) in enumerate(held):
                d = np.hypot(*(snap.world - w).T)
                d[taken] = np.inf
                k = int(np.argmin(d))
                if d[k] <= runner.params.tentative_radius:
                    first[a] = k
                    taken.append(k)
            if taken:
                runner.preint = snap.restore(ekf)
                for k in taken:
                    ekf.add_lamp(snap.z[k], snap.r[k])
                if runner.preint.steps:
                    runner.predict()
        for (j, _), k in zip(held, first, strict=True):
            if k < 0:
                ekf.add_lamp(z[j], r[j])
        return len(held)
