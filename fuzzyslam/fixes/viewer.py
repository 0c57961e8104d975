"""The fixes as a viewer shows them, for ``run``'s estimates.mcap (ROS 2 messages as CDR
bytes, ``streams/cdr_encode.py``): one visualization_msgs/MarkerArray per formed fix, at the
ring's time, in the map frame. Colours (Okabe-Ito, colour-blind safe): bluish green when the
filter took the fix, vermillion when it was refused (gated, ambiguous, ...).

- heading fixes (``topics.heading_fixes``): a line through the robot of the corridor
  direction the FLM measured, placed with the filter's predicted heading (reference angle
  + predicted - measured heading): it lies along the map's corridor when the prediction
  agrees with the measurement, and turned by the heading error when it does not;
- pose fixes (``topics.pose_fixes``): an arrow at the matched pose (FLM against FGM).

Marker ids are constant per namespace, so a viewer shows the latest fix of each kind.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.cdr_encode import MarkerSpec, encode_marker_array

ACCEPTED = (0.0, 0.62, 0.45, 1.0)  # bluish green
REFUSED = (0.84, 0.37, 0.0, 1.0)  # vermillion
HEADING_LINE_M = 2.0  # length of a heading fix's line, m


def heading_fix_messages(
    decisions: Sequence[Any], ref_angles: dict[int, float], topic: str, frame: str = "map"
) -> list[tuple[str, str, Any, float]]:
    """(topic, type, MarkerArray CDR bytes, t) of every formed heading fix (finite measured heading
    and robot position, a known corridor): a line of ``HEADING_LINE_M`` through the robot
    at reference angle + predicted - measured (module docstring).

    Parameters
    ----------
    decisions : sequence of HeadingDecision
        The aid's decisions.
    ref_angles : dict of int to float
        Reference angle (rad) of each corridor id.
    topic : str
        The topic.
    frame : str
        The markers' frame.

    Returns
    -------
    list of (str, str, bytes, float)
    """
    out = []
    for d in decisions:
        ang = ref_angles.get(int(d.corridor))
        vals = (d.measured, d.predicted, d.x, d.y)
        if ang is None or not all(np.isfinite(v) for v in vals):
            continue
        a = ang + d.predicted - d.measured
        u = 0.5 * HEADING_LINE_M * np.array([np.cos(a), np.sin(a)])
        c = np.array([d.x, d.y])
        m = MarkerSpec(d.t, frame, "heading_fix", 0, 5, scale=(0.05, 0.0, 0.0),
                       rgba=ACCEPTED if d.accepted else REFUSED, points=np.array([c - u, c + u]),
                       z=0.05)  # fmt: skip
        out.append((topic, M.MARKER_ARRAY, encode_marker_array([m]), float(d.t)))
    return out


def pose_fix_messages(
    decisions: Sequence[Any], topic: str, frame: str = "map"
) -> list[tuple[str, str, Any, float]]:
    """(topic, type, MarkerArray CDR bytes, t) of every pose match (finite matched pose): an arrow
    (0.5 m) at the matched pose, coloured by whether the filter took it.

    Parameters
    ----------
    decisions : sequence of PoseDecision
        The aid's decisions.
    topic : str
        The topic.
    frame : str
        The markers' frame.

    Returns
    -------
    list of (str, str, bytes, float)
    """
    out = []
    for d in decisions:
        p = np.asarray(d.pose, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            continue
        m = MarkerSpec(d.t, frame, "pose_fix", 0, 0, (p[0], p[1], p[2]), 0.05, (0.5, 0.08, 0.08),
                       ACCEPTED if d.accepted else REFUSED)  # fmt: skip
        out.append((topic, M.MARKER_ARRAY, encode_marker_array([m]), float(d.t)))
    return out


def map_messages(viewer_map: Any, topics: Any, start: float | None) -> list:
    """/map, its conflict layer and references (maps/viewer.py) of the FGM the fixes use,
    stamped ``start`` (the log's start); nothing when ``viewer_map`` or ``start`` is None.
    ``viewer_map``: (BeliefMap, [(id, name, angle, polygon)]).

    Parameters
    ----------
    viewer_map : tuple or None
        (BeliefMap, [(id, name, angle, polygon (K, 2))]).
    topics : Topics
        The config's topics.
    start : float or None
        The stamp (s).

    Returns
    -------
    list of (str, str, bytes, float)
        The messages as CDR bytes.
    """
    if viewer_map is None or start is None:
        return []
    from fuzzyslam.maps.viewer import fgm_messages

    fgm, refs = viewer_map
    return fgm_messages(fgm, refs, float(start), topics)
