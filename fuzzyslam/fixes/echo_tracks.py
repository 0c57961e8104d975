"""Heading fixes from the tracks of a sonar ring's echoes over travel (beyond the paper;
``fixes.heading_source: echo_tracks``, docs/models.md sec. 9).

A sonar returns the nearest surface in its cone, so one ring of a few sonars holds no
line. But while the robot drives along a wall, each sonar's echoes, placed where its axis
says, stay at a constant offset from that wall: the track of one sonar's echoes over the
last ``track_window_m`` metres of travel is a line parallel to the wall (the tangent
model of Leonard and Durrant-Whyte 1992, the wall tangent to the echo arcs, with the
arcs' order in time instead of a Hough vote on 10 cm cells). The rings are placed by
their DEAD-RECKONING relative poses (``EkfSlam.odometry_pose``: smooth over a few metres,
and independent of the fixes themselves), each sonar's track is cut into straight
segments by the laser's line fit (:func:`fuzzyslam.fixes.scan_lines.fit_segments`, the
``scan_line_*`` keys, neighbours up to ``track_gap`` m apart), and the heading is
measured from them as for a scan (:func:`fuzzyslam.fixes.scan_heading.measure_heading`).

Windows that share rings have correlated errors: a fix is formed once the robot has
travelled ``track_fix_travel`` m since the last one, with its sigma multiplied by
sqrt(max(1, track_window_m / track_fix_travel)) (each metre's information counted once,
as for the multi-ring FLM's ``flm_fix_every``).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

from fuzzyslam.fixes.params import FixParams
from fuzzyslam.fixes.references import Reference
from fuzzyslam.fixes.scan_heading import ScanLineHeadingAid
from fuzzyslam.fixes.scan_lines import Segments, fit_segments, scan_end_points
from fuzzyslam.se2 import between, transform_points
from fuzzyslam.slam.events import FilterView


class EchoTracks:
    """The rings of the last ``window_m`` metres of travel (at most ``window_s`` seconds,
    ``max_rings`` rings) with their dead-reckoning poses."""

    def __init__(self, window_m: float, window_s: float, max_rings: int = 256) -> None:
        self.window_m = float(window_m)
        self.window_s = float(window_s)
        self.rings: deque[tuple[float, np.ndarray, np.ndarray, float]] = deque(maxlen=max_rings)

    def push(self, t: float, pose: np.ndarray, points: np.ndarray) -> None:
        """Add a ring's end points (M, 2) (robot frame) taken at dead-reckoning ``pose``."""
        pose = np.asarray(pose, dtype=float).reshape(3)
        if self.rings and (t < self.rings[-1][0] or points.shape != self.rings[-1][2].shape):
            self.rings.clear()  # time went back or the ring changed: start afresh
        s = 0.0
        if self.rings:
            s = self.rings[-1][3] + float(np.hypot(*(pose[:2] - self.rings[-1][1][:2])))
        self.rings.append((float(t), pose, np.asarray(points, dtype=float), s))
        while len(self.rings) > 1 and (
            s - self.rings[0][3] > self.window_m or t - self.rings[0][0] > self.window_s
        ):
            self.rings.popleft()

    @property
    def travel(self) -> float:
        """Distance travelled (m, dead reckoning) since the first ring pushed."""
        return self.rings[-1][3] if self.rings else 0.0

    def tracks(self) -> np.ndarray:
        """(M (K + 1), 2): each sensor's K echoes in time order in the newest ring's frame,
        the sensors' tracks separated by a NaN row (no link across them)."""
        poses = np.array([r[1] for r in self.rings])
        rel = between(poses[-1], poses)  # (K, 3) the rings' poses in the newest frame
        pts = np.stack([transform_points(rel[k], r[2]) for k, r in enumerate(self.rings)])
        k, m = pts.shape[0], pts.shape[1]
        out = np.full((m, k + 1, 2), np.nan)
        out[:, :k] = pts.transpose(1, 0, 2)
        return out.reshape(m * (k + 1), 2)


class EchoTrackHeadingAid(ScanLineHeadingAid):
    """Heading fixes from the echo tracks of a sonar ring (module docstring)."""

    def __init__(self, refs: Sequence[Reference], params: FixParams, start_time: float = 0.0):
        super().__init__(refs, params, start_time)
        p = params
        self.tracks = EchoTracks(p.track_window_m, p.track_window_s)
        self._last_fix_travel = -math.inf
        self._scale = math.sqrt(max(1.0, p.track_window_m / p.track_fix_travel))

    def segments(
        self, t: float, ring: Any, mounts: np.ndarray, ekf: FilterView
    ) -> tuple[Segments | None, float]:
        p = self.params
        pts = scan_end_points(ring.ranges, ring.max_range, mounts)
        self.tracks.push(t, ekf.odometry_pose, pts)
        if self.tracks.travel - self._last_fix_travel < p.track_fix_travel:
            return None, 1.0
        self._last_fix_travel = self.tracks.travel
        segs = fit_segments(
            self.tracks.tracks(),
            p.scan_line_points,
            p.scan_line_tolerance,
            p.track_gap,
            p.scan_line_min_length,
        )
        return segs, self._scale
