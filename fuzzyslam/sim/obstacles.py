"""Unexpected obstacles and people: objects the sonars see and the map does not (pure).

Beyond the paper (issue 8; the paper's sec. 4 suggests the map could spot "unusual
obstacles or people walking down the corridors"). From ``scenario.obstacles``:

- ``box``: a static rectangle (centre, size = [length, width], angle_deg). Its four
  faces are added to the wall segments for the sonar ray casting, so they reflect
  specularly like the walls (flat faces: furniture, crates);
- ``disc``: a person, a circle of ``radius`` walking back and forth along the
  polyline ``path`` at ``speed`` (a triangle wave in arc length, starting at the
  first point when it appears). A person is a rough, rounded reflector: a ray that
  meets the circle echoes whatever its incidence (``sim.sonar`` with ``discs``).

Each object is present from the start of run ``from_run`` to the end of run
``to_run``. Collisions with the robot are not simulated: place objects off its path.
The truth goes into the log as the metadata record ``fuzzyslam.obstacles``
(:func:`obstacles_record`): per object its id, kind, presence interval, shape
(box polygon, or disc radius) and its track [[t, x, y], ...] at the sonar ring times.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fuzzyslam.errors import ConfigError
from fuzzyslam.se2 import rot

OBSTACLES_KEY = "fuzzyslam.obstacles"


@dataclass(frozen=True)
class Track:
    """One object of the scenario: shape and presence interval [t0, t1]."""

    id: int
    kind: str  # "box" | "disc"
    t0: float
    t1: float
    polygon: np.ndarray  # (4, 2) box corners (boxes), or (0, 2)
    radius: float  # discs
    path: np.ndarray  # (K, 2) polyline walked back and forth (discs)
    speed: float

    def present(self, t: float) -> bool:
        """Whether the obstacle is there at time ``t``.

        Parameters
        ----------
        t : float
            Log time (s).

        Returns
        -------
        bool
            t0 <= t <= t1.
        """
        return self.t0 <= t <= self.t1

    def position(self, t: float) -> np.ndarray:
        """Centre at time t: the box centre, or the disc on its back-and-forth walk.

        Parameters
        ----------
        t : float
            Log time (s).

        Returns
        -------
        ndarray, shape (2,)
        """
        if self.kind == "box":
            return self.polygon.mean(axis=0)
        seg = np.diff(self.path, axis=0)
        lens = np.linalg.norm(seg, axis=1)
        total = float(lens.sum())
        if total <= 0:
            return self.path[0].copy()
        s = np.mod(self.speed * max(t - self.t0, 0.0), 2 * total)
        s = s if s <= total else 2 * total - s  # triangle wave: there and back
        cum = np.concatenate([[0.0], np.cumsum(lens)])
        i = min(max(int(np.searchsorted(cum, s, side="right")) - 1, 0), len(lens) - 1)
        return self.path[i] + seg[i] * ((s - cum[i]) / max(lens[i], 1e-12))


def box_polygon(centre, size, angle_deg: float) -> np.ndarray:
    """Corners (4, 2) of a rectangle of size [length, width] turned by angle_deg.

    Parameters
    ----------
    centre : array_like, shape (2,)
        The box's centre (m).
    size : array_like, shape (2,)
        [length, width] (m).
    angle_deg : float
        The turn of its length axis (deg).

    Returns
    -------
    ndarray, shape (4, 2)
    """
    a = np.radians(angle_deg)
    r = rot(a)
    half = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * (np.asarray(size, float) / 2)
    return half @ r.T + np.asarray(centre, float)


def plan_tracks(obstacles, run_intervals: dict[int, tuple[float, float]], source: str):
    """Tracks of the configured obstacles whose runs are simulated (validated).

    Parameters
    ----------
    obstacles : list
        The config's ``scenario.obstacles``.
    run_intervals : dict of int to (float, float)
        Start and end (s) of each simulated run.
    source : str
        The config's name (for error messages).
    """
    out = []
    for i, o in enumerate(obstacles):
        where = f"'scenario.obstacles[{i}]'"
        if o.to_run < o.from_run:
            raise ConfigError(source, f"{where}: to_run must be >= from_run")
        runs = [r for r in range(o.from_run, o.to_run + 1) if r in run_intervals]
        if not runs:
            continue
        t0, t1 = run_intervals[runs[0]][0], run_intervals[runs[-1]][1]
        if o.kind == "box":
            if len(o.centre) != 2 or len(o.size) != 2 or min(o.size) <= 0:
                raise ConfigError(source, f"{where}: a box needs centre [x, y], size [l, w] > 0")
            poly = box_polygon(o.centre, o.size, o.angle_deg)
            out.append(Track(i, "box", t0, t1, poly, 0.0, np.zeros((0, 2)), 0.0))
        else:
            path = np.asarray(o.path, dtype=float)
            if path.ndim != 2 or path.shape[1] != 2 or len(path) < 1:
                raise ConfigError(source, f"{where}: a disc needs a path of [x, y] points")
            if len(path) == 1:
                path = np.vstack([path, path])
            out.append(Track(i, "disc", t0, t1, np.zeros((0, 2)), o.radius, path, o.speed))
    return out


def box_segments(tracks, t: float) -> np.ndarray:
    """Faces (K, 4) x0 y0 x1 y1 of the boxes present at t.

    Parameters
    ----------
    tracks : list of Track
        :func:`plan_tracks`.
    t : float
        Log time (s).

    Returns
    -------
    ndarray, shape (K, 4)
    """
    polys = [tr.polygon for tr in tracks if tr.kind == "box" and tr.present(t)]
    if not polys:
        return np.zeros((0, 4))
    return np.concatenate([np.hstack([p, np.roll(p, -1, axis=0)]) for p in polys])


def discs_at(tracks, t: float, present_at: float | None = None) -> np.ndarray:
    """Circles (J, 3) x y radius of the people present at t (or at ``present_at``: the
    people of a ring's first firing, where they are as a later sonar of it fires).

    Parameters
    ----------
    tracks : list of Track
        :func:`plan_tracks`.
    t : float
        Log time (s).
    present_at : float, optional
        The time whose people are taken (default ``t``).

    Returns
    -------
    ndarray, shape (J, 3)
    """
    at = t if present_at is None else present_at
    rows = [[*tr.position(t), tr.radius] for tr in tracks if tr.kind == "disc" and tr.present(at)]
    return np.asarray(rows, dtype=float).reshape(-1, 3)


def obstacles_record(tracks, ring_times: np.ndarray) -> dict:
    """The ``fuzzyslam.obstacles`` metadata: shapes, intervals and tracks at ring times.

    Parameters
    ----------
    tracks : list of Track
        :func:`plan_tracks`.
    ring_times : ndarray, shape (N,)
        The sonar rings' times (s).

    Returns
    -------
    dict
        The metadata record (JSON-ready).
    """
    items = []
    for tr in tracks:
        ts = ring_times[(ring_times >= tr.t0) & (ring_times <= tr.t1)]
        if tr.kind == "box":
            c = tr.position(0.0)
            track = (
                [[round(float(t), 4), float(c[0]), float(c[1])] for t in ts[[0, -1]]]
                if len(ts)
                else []
            )
        else:
            track = [
                [round(float(t), 4), *(round(float(v), 4) for v in tr.position(t))] for t in ts
            ]
        items.append(
            {
                "id": tr.id,
                "kind": tr.kind,
                "t_start": float(tr.t0),
                "t_end": float(tr.t1),
                "polygon": tr.polygon.tolist(),
                "radius": float(tr.radius),
                "track": track,
            }
        )
    return {"obstacles": items}


def ray_circle_hits(origins: np.ndarray, dirs: np.ndarray, discs: np.ndarray) -> np.ndarray:
    """Distance (R,) along each unit ray to its first circle; inf where none.

    |p + t d - c|^2 = rho^2  ->  t = -b - sqrt(b^2 - k), b = d.(p - c), k = |p - c|^2 - rho^2;
    a ray starting inside a circle (k < 0) is not counted.

    Parameters
    ----------
    origins : ndarray, shape (R, 2)
        Ray origins.
    dirs : ndarray, shape (R, 2)
        Unit directions.
    discs : ndarray, shape (J, 3) or (R, J, 3)
        Circles (x, y, radius), the same for every ray or each ray's own.

    Returns
    -------
    ndarray, shape (R,)
    """
    if discs.shape[-2] == 0:
        return np.full(len(origins), np.inf)
    per_ray = discs if discs.ndim == 3 else discs[None]
    pc = origins[:, None, :] - per_ray[:, :, :2]
    b = np.sum(dirs[:, None, :] * pc, axis=2)
    k = np.sum(pc * pc, axis=2) - per_ray[:, :, 2] ** 2
    disc = b * b - k
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    ok = (disc >= 0) & (k > 0) & (t > 1e-6)
    return np.where(ok, t, np.inf).min(axis=1)
