"""The maps as a viewer (Foxglove, RViz) shows them: ROS 2 messages of an FGM and its
corridor references (nav_msgs/OccupancyGrid, visualization_msgs/MarkerArray).

The grids have the geometry of the nav2 files ``mapio.save_nav2`` writes (the same
resolution, width, height and lower-left origin as fgm.yaml and fgm.pgm): row 0 of
``OccupancyGrid.data`` is the map's lowest y, as the FGM's arrays. Messages are CDR bytes
(``streams/cdr_encode.py``: rosbags' bytes without its typestore), written by the caller
through ``streams/writer.LogWriter``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fuzzyslam.maps.grid import BeliefMap
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.cdr_encode import MarkerSpec, encode_marker_array, encode_occupancy_grid

UNKNOWN_T = 0.9  # m(Theta) above this: unknown (-1), as the nav2 PGM (mapio.occupancy_image)
REFERENCE_COLOUR = (0.0, 0.45, 0.70, 1.0)  # blue (Okabe-Ito), colour-blind safe


def occupancy_values(bm: BeliefMap) -> np.ndarray:
    """(ny, nx) int8 occupancy in percent, 100 BetP(O) rounded; -1 where nothing is known
    (m(Theta) > ``UNKNOWN_T``, the nav2 PGM's unknown).

    Parameters
    ----------
    bm : BeliefMap
        The FGM (masses (ny, nx)).

    Returns
    -------
    ndarray of int8, shape (ny, nx)
    """
    v = np.rint(100.0 * np.clip(bm.pignistic_occupied(), 0.0, 1.0)).astype(np.int8)
    v[bm.m_t > UNKNOWN_T] = -1
    return v


def conflict_values(bm: BeliefMap) -> np.ndarray:
    """(ny, nx) int8 conflict mass m(emptyset) in percent; -1 where no reading ever fell
    (m(Theta) = 1).

    Parameters
    ----------
    bm : BeliefMap
        The FGM (masses (ny, nx)).

    Returns
    -------
    ndarray of int8, shape (ny, nx)
    """
    v = np.rint(100.0 * np.clip(bm.m_c, 0.0, 1.0)).astype(np.int8)
    v[bm.m_t >= 1.0 - 1e-12] = -1
    return v


def grid_message(bm: BeliefMap, values: np.ndarray, t: float, frame: str = "map") -> bytes:
    """nav_msgs/OccupancyGrid (CDR bytes) of ``values`` (ny, nx) on the FGM's grid.

    Parameters
    ----------
    bm : BeliefMap
        The FGM (masses (ny, nx)).
    values : ndarray of int8, shape (ny, nx)
        The cells' values.
    t : float
        The stamp (s).
    frame : str
        The frame.

    Returns
    -------
    bytes
        The message's CDR payload.
    """
    g = bm.grid
    return encode_occupancy_grid(t, frame, values, g.resolution, (g.origin[0], g.origin[1]))


def reference_markers(
    refs: Sequence[tuple[int, str, float, np.ndarray]], t: float, frame: str = "map"
) -> bytes:
    """visualization_msgs/MarkerArray (CDR bytes) of corridor references given as (id, name,
    angle (rad, mod pi), region polygon (K, 2)): per reference its region (closed line strip,
    namespace ``region``), its reference direction through the region's centroid (a
    line as long as the region's extent along it, ``direction``) and a text label
    ``name angle deg`` (``label``); marker id = reference id.

    Parameters
    ----------
    refs : sequence of (int, str, float, ndarray of shape (K, 2))
        id, name, angle (rad), region polygon.
    t : float
        The stamp (s).
    frame : str
        The frame.

    Returns
    -------
    bytes
        The message's CDR payload.
    """
    markers = []
    for rid, name, angle, poly in refs:
        poly = np.asarray(poly, dtype=float).reshape(-1, 2)
        c = poly.mean(axis=0)
        d = np.array([np.cos(angle), np.sin(angle)])
        s = (poly - c) @ d
        half = max(0.5 * float(s.max() - s.min()), 0.5)
        ring = np.vstack([poly, poly[:1]])
        markers.append(
            MarkerSpec(t, frame, "region", rid, 4, scale=(0.03, 0.0, 0.0), rgba=REFERENCE_COLOUR,
                       points=ring, z=0.01)
        )  # fmt: skip
        markers.append(
            MarkerSpec(t, frame, "direction", rid, 5, scale=(0.06, 0.0, 0.0),
                       rgba=REFERENCE_COLOUR, points=np.array([c - half * d, c + half * d]),
                       z=0.02)
        )  # fmt: skip
        markers.append(
            MarkerSpec(t, frame, "label", rid, 9, (c[0], c[1], 0.0), 0.3, (0.0, 0.0, 0.3),
                       (1.0, 1.0, 1.0, 1.0), text=f"{name} {np.rad2deg(angle) % 180.0:.2f} deg")
        )  # fmt: skip
    return encode_marker_array(markers)


def fgm_messages(
    bm: BeliefMap,
    refs: Sequence[tuple[int, str, float, np.ndarray]],
    t: float,
    topics: Any,
    frame: str = "map",
) -> list[tuple[str, str, bytes, float]]:
    """(topic, type, CDR bytes, t) of an FGM: ``topics.map`` (occupancy),
    ``topics.map_conflict`` (the conflict layer), ``topics.map_references`` (the corridor
    references, when any).

    Parameters
    ----------
    bm : BeliefMap
        The FGM (masses (ny, nx)).
    refs : sequence of (int, str, float, ndarray of shape (K, 2))
        The corridor references.
    t : float
        The stamp (s).
    topics : Topics
        The config's topics.
    frame : str
        The frame.

    Returns
    -------
    list of (str, str, bytes, float)
    """
    out = [
        (topics.map, M.OCCUPANCY_GRID, grid_message(bm, occupancy_values(bm), t, frame), t),
        (topics.map_conflict, M.OCCUPANCY_GRID, grid_message(bm, conflict_values(bm), t, frame),
         t),
    ]  # fmt: skip
    if refs:
        out.append((topics.map_references, M.MARKER_ARRAY, reference_markers(refs, t, frame), t))
    return out
