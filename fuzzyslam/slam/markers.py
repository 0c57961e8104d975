"""The /slam/landmarks markers of estimates.mcap: one flat ellipse per lamp."""

from __future__ import annotations

import numpy as np

from fuzzyslam.streams import messages as M


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
    markers = []
    for i, (xy, c) in enumerate(zip(lamps, covs, strict=True)):
        w, v = np.linalg.eigh(c)
        ang = float(np.arctan2(v[1, 1], v[0, 1]))
        sx, sy = (max(6.0 * float(np.sqrt(max(e, 0.0))), 0.05) for e in (w[1], w[0]))
        markers.append(
            M.marker(
                t,
                "map",
                "lamps",
                i,
                2,
                (xy[0], xy[1], ang),
                2.5,
                (sx, sy, 0.02),
                (1.0, 0.8, 0.1, 0.8),
            )
        )
    return M.marker_array(markers)
