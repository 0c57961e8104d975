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
next frame's are). Any update before the first birth (a heading fix) ends the anchor:
the rewind would no longer be exact.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from fuzzyslam.slam.ekf import EkfSlam, lamp_init


@dataclass
class StartAnchor:
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
        A copy of the runner's preintegrator (its calibration instrument included).
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

    @classmethod
    def take(cls, ekf: EkfSlam, preint, t: float, z: np.ndarray, r: np.ndarray) -> StartAnchor:
        """The anchor of the filter as it stands (an empty map, no update so far).

        Parameters
        ----------
        ekf : EkfSlam
            The filter (no lamps).
        preint : Preintegrator
            The runner's preintegrator (flushed: no pending step).
        t : float
            The frame's time (s).
        z : ndarray, shape (m, 2)
            The frame's detections.
        r : ndarray, shape (m, 2, 2)
            Their covariances.

        Returns
        -------
        StartAnchor
        """
        pose = ekf.pose
        world = np.array([lamp_init(pose, zj)[0] for zj in z]).reshape(-1, 2)
        return cls(
            t,
            ekf.x.copy(),
            ekf.P.copy(),
            ekf.odometry_pose.copy(),
            copy.deepcopy(preint),
            np.array(z, dtype=float).reshape(-1, 2),
            np.array(r, dtype=float).reshape(-1, 2, 2),
            world,
        )

    def give_birth(self, ekf: EkfSlam, worlds: list[np.ndarray], radius: float) -> list[int]:
        """Rewind the filter to the anchor and add the lamps confirmed at ``worlds`` from
        their sightings in the anchor frame (each the nearest detection there within
        ``radius``, one lamp per detection); the caller replays the odometry since. The
        filter is left as it was when the anchor frame saw none of them.

        Parameters
        ----------
        ekf : EkfSlam
            The filter (no lamps; updated in place).
        worlds : list of ndarray, shape (2,)
            The confirming sightings (world frame).
        radius : float
            The tentative lamps' radius (m).

        Returns
        -------
        list of int
            The indices into ``worlds`` that the anchor frame did not see (not added).
        """
        taken: list[int] = []
        for w in worlds:
            d = np.hypot(*(self.world - np.asarray(w, dtype=float)).T)
            d[[k for k in taken if k >= 0]] = np.inf
            k = int(np.argmin(d)) if len(d) else -1
            taken.append(k if k >= 0 and d[k] <= radius else -1)
        born = [k for k in taken if k >= 0]
        if born:
            self.restore(ekf)
            for k in born:
                ekf.add_lamp(self.z[k], self.r[k])
        return [a for a, k in enumerate(taken) if k < 0]

    def restore(self, ekf: EkfSlam) -> None:
        """Put the filter back as it was at the anchor (its map still empty).

        Parameters
        ----------
        ekf : EkfSlam
            The filter (updated in place).
        """
        if ekf.n_lamps:
            raise ValueError("StartAnchor.restore: the map is no longer empty")
        ekf.x[:] = self.x
        ekf.P[:, :] = self.p
        ekf.odometry_pose = self.odometry_pose.copy()
