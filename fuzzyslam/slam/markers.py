"""The /slam/landmarks markers of estimates.mcap: one flat ellipse per lamp."""

from __future__ import annotations

import numpy as np

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.cdr_encode import encode_markers

_Z, _SCALE_Z, _RGBA = 2.5, 0.02, (1.0, 0.8, 0.1, 0.8)  # height, thickness, colour


def _ellipses(lamps: np.ndarray, covs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per lamp (x, y, angle of the major axis) and the 3-sigma axes (at least 5 cm)."""
    poses, scales = [], []
    for xy, c in zip(lamps, covs, strict=True):
        w, v = np.linalg.eigh(c)
        ang = float(np.arctan2(v[1, 1], v[0, 1]))
        poses.append((xy[0], xy[1], ang))
        scales.append([max(6.0 * float(np.sqrt(max(e, 0.0))), 0.05) for e in (w[1], w[0])])
    return np.array(poses, dtype=float).reshape(-1, 3), np.array(scales).reshape(-1, 2)


def lamp_markers(t: float, lamps: np.ndarray, covs: np.ndarray) -> object:
    """One flat ellipse per lamp (3 sigma, at least 5 cm across); marker id = lamp id.

    Parameters
    ----------
    t : float
        Stamp (s).
    lamps : ndarray, shape (n, 2)
        Lamp positions in the map frame.
    covs : ndarray, shape (n, 2, 2)
        Their covariances.

    Returns
    -------
    object
        A visualization_msgs/MarkerArray.
    """
    poses, scales = _ellipses(lamps, covs)
    markers = [
        M.marker(t, "map", "lamps", i, 2, tuple(p), _Z, (*s, _SCALE_Z), _RGBA)
        for i, (p, s) in enumerate(zip(poses.tolist(), scales.tolist(), strict=True))
    ]
    return M.marker_array(markers)


def lamp_markers_cdr(t: float, lamps: np.ndarray, covs: np.ndarray) -> bytes:
    """The CDR bytes of :func:`lamp_markers` (``streams.cdr_encode.encode_markers``: 10x
    cheaper than building and serialising the message).

    Parameters
    ----------
    t : float
        Stamp (s).
    lamps : ndarray, shape (n, 2)
        Lamp positions in the map frame.
    covs : ndarray, shape (n, 2, 2)
        Their covariances.

    Returns
    -------
    bytes
        A little-endian CDR visualization_msgs/MarkerArray.
    """
    poses, scales = _ellipses(lamps, covs)
    return encode_markers(t, "map", "lamps", 2, poses, _Z, scales, _SCALE_Z, _RGBA)
