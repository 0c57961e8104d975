"""Sonar ring physics: cone ray casting with specular reflection (pure, vectorised).

Model (docs/models.md sec. 11; Moravec 1990; Leonard & Durrant-Whyte, "Directed Sonar
Sensing for Mobile Robot Navigation", 1992, ch. 2):

- each sensor casts ``rays_per_cone`` rays evenly across its cone (+-fov/2);
- a ray that meets a wall at incidence angle (to the wall normal) below the critical
  angle echoes back along its own path: the reading is the path length so far;
- above it the wall is a mirror: the ray reflects (d' = d - 2 (d.n) n) and travels
  on, up to ``max_bounces`` times, so a bounced echo returns long;
- a reflected ray heading back toward the sensor within ``return_angle`` (a concave
  corner acting as a corner reflector) echoes with half the closed path length
  (whether the way back is clear is not checked: in a corridor loop it is);
- the sensor reports the first echo of any of its rays (the minimum); none within
  max range reads max_range (no echo);
- the reading gets ~1 % multiplicative noise, an occasional crosstalk reading
  (uniform between min range and the true reading), is clipped to
  [min_range, max_range] and quantised to ``quantization`` (1 inch).

All rays of a ring are intersected with all wall segments in one numpy operation.
"""

from __future__ import annotations

import numpy as np

from fuzzyslam.se2 import compose
from fuzzyslam.sim.obstacles import ray_circle_hits
from fuzzyslam.sim.params import SonarParams

EPS = 1e-9


def cast_rays(walls: np.ndarray, origins: np.ndarray, dirs: np.ndarray):
    """Nearest wall hit of each ray: (distance (R,), segment index (R,)); inf/-1 if none.

    Ray p + t d meets segment a + u (b - a) where, with cross(x, y) = x0 y1 - x1 y0,
    t = cross(a - p, e) / cross(d, e) and u = cross(a - p, d) / cross(d, e), e = b - a;
    a hit needs t > 0 and 0 <= u <= 1.

    Parameters
    ----------
    walls : ndarray, shape (S, 4)
        Wall segments (ax, ay, bx, by).
    origins : ndarray, shape (R, 2)
        Ray origins.
    dirs : ndarray, shape (R, 2)
        Ray directions (unit).

    Returns
    -------
    dist : ndarray, shape (R,)
        Distance to the nearest hit (inf: none).
    seg : ndarray of int, shape (R,)
        Its segment (-1: none).
    """
    a = walls[None, :, 0:2]
    e = walls[None, :, 2:4] - walls[None, :, 0:2]
    p = origins[:, None, :]
    d = dirs[:, None, :]
    ap = a - p
    denom = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ap[..., 0] * e[..., 1] - ap[..., 1] * e[..., 0]) / denom
        u = (ap[..., 0] * d[..., 1] - ap[..., 1] * d[..., 0]) / denom
    ok = (np.abs(denom) > EPS) & (t > 1e-6) & (u >= 0.0) & (u <= 1.0)
    t = np.where(ok, t, np.inf)
    idx = np.argmin(t, axis=1)
    best = t[np.arange(len(t)), idx]
    return best, np.where(np.isfinite(best), idx, -1)


def wall_normals(walls: np.ndarray) -> np.ndarray:
    """Unit normals (S, 2) of wall segments (either side).

    Parameters
    ----------
    walls : ndarray, shape (S, 4)
        Wall segments (ax, ay, bx, by).

    Returns
    -------
    ndarray, shape (S, 2)
    """
    e = walls[:, 2:4] - walls[:, 0:2]
    n = np.column_stack([-e[:, 1], e[:, 0]])
    return n / np.linalg.norm(n, axis=1)[:, None]


def ideal_ranges(
    walls: np.ndarray,
    sensors: np.ndarray,
    params: SonarParams,
    discs: np.ndarray | None = None,
) -> np.ndarray:
    """Noise-free first-echo range of each sensor; inf where no echo.

    ``sensors`` (M, 3) are world poses (x, y, yaw) of the transducers. ``discs`` (J, 3)
    x y radius: people (``sim.obstacles``), rough reflectors: a ray meeting one before
    any wall echoes from it whatever its incidence.

    Parameters
    ----------
    walls : ndarray, shape (S, 4)
        Wall segments.
    sensors : ndarray, shape (M, 3)
        The transducers' world poses.
    params : SonarParams
        The sonar model (cone, incidence, range).
    discs : ndarray, shape (J, 3) or (M, J, 3), optional
        People (x, y, radius), or each sensor's own (:func:`ideal_ranges_many`).

    Returns
    -------
    ndarray, shape (M,)
        Ranges (m); inf: no echo.
    """
    m = len(sensors)
    n = params.rays_per_cone
    half = np.radians(params.fov_deg) / 2.0
    offs = np.linspace(-half, half, n) if n > 1 else np.zeros(1)
    ang = (sensors[:, 2:3] + offs[None, :]).reshape(-1)
    src = np.repeat(sensors[:, :2], n, axis=0)
    org = src.copy()
    d = np.column_stack([np.cos(ang), np.sin(ang)])
    normals = wall_normals(walls)
    cos_crit = np.cos(np.radians(params.critical_angle_deg))
    cos_ret = np.cos(np.radians(params.return_angle_deg))
    path = np.zeros(len(ang))
    echo = np.full(len(ang), np.inf)
    alive = np.ones(len(ang), dtype=bool)
    if discs is not None and discs.ndim == 3:
        discs = np.repeat(discs, n, axis=0)  # each ray its sensor's people
    for bounce in range(params.max_bounces + 1):
        t, seg = cast_rays(walls, org, d)
        if discs is not None and discs.shape[-2]:
            tc = ray_circle_hits(org, d, discs)
            person = alive & (tc < t)
            echo = np.where(person, path + tc, echo)
            alive &= ~person
        hit = alive & (seg >= 0)
        alive &= hit
        nrm = normals[np.maximum(seg, 0)]
        dn = np.sum(d * nrm, axis=1)
        path = path + np.where(hit, t, 0.0)
        direct = hit & (np.abs(dn) >= cos_crit)
        echo = np.where(direct, path, echo)
        alive &= ~direct
        if bounce == params.max_bounces:
            break
        org = np.where(alive[:, None], org + t[:, None] * d, org)
        d = np.where(alive[:, None], d - 2.0 * dn[:, None] * nrm, d)
        back = src - org
        dist_back = np.linalg.norm(back, axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            cos_back = np.sum(d * back, axis=1) / dist_back
        ret = alive & (cos_back >= cos_ret) & (dist_back > EPS)
        echo = np.where(ret, 0.5 * (path + dist_back), echo)
        alive &= ~ret
    return echo.reshape(m, n).min(axis=1)


def measure(ideal: np.ndarray, params: SonarParams, rng: np.random.Generator) -> np.ndarray:
    """Readings from ideal ranges: noise, crosstalk, clipping and quantisation.

    Always draws the same number of random numbers per call (determinism).

    Parameters
    ----------
    ideal : ndarray, shape (M,)
        Noise-free ranges (inf: no echo).
    params : SonarParams
        Noise, crosstalk, maximum range, quantisation.
    rng : numpy.random.Generator
        The sonar's random stream.

    Returns
    -------
    ndarray, shape (M,)
        Readings (m); the maximum range for no echo.
    """
    m = len(ideal)
    noise = rng.standard_normal(m)
    cross = rng.random(m) < params.crosstalk_prob
    cross_u = rng.random(m)
    r = ideal * (1.0 + params.noise_frac * noise)
    no_echo = ~np.isfinite(ideal) | (r >= params.max_range)
    top = np.where(np.isfinite(ideal), np.minimum(ideal, params.max_range), params.max_range)
    r = np.where(cross, params.min_range + cross_u * (top - params.min_range), r)
    no_echo &= ~cross
    if params.quantization > 0:
        r = np.round(r / params.quantization) * params.quantization
    r = np.clip(r, params.min_range, params.max_range)
    return np.where(no_echo, params.max_range, r)


def reading_variance(r: np.ndarray, params: SonarParams) -> np.ndarray:
    """The variance of :func:`measure`'s noise about a reading, as a Range message carries
    it (``variance``, Iron on): the proportional noise at the reading's range plus the
    quantisation's, ``(noise_frac r)^2 + quantization^2 / 12``; 0 (REP 117 and the
    message's comment: unknown) for a no-echo reading (the maximum range), which
    measures no range. Crosstalk (an outlier, not noise) is not in it.

    Parameters
    ----------
    r : ndarray, shape (M,)
        Readings (m), as :func:`measure` returns them.
    params : SonarParams
        Noise, quantisation and maximum range.

    Returns
    -------
    ndarray, shape (M,)
        Variances (m^2).
    """
    r = np.asarray(r, dtype=float)
    var = (params.noise_frac * r) ** 2 + params.quantization**2 / 12.0
    return np.where(r >= params.max_range, 0.0, var)


def sensor_poses(pose: np.ndarray, mounts: np.ndarray) -> np.ndarray:
    """World poses (M, 3) of sensors mounted at ``mounts`` (M, 3) on a robot at ``pose``.

    Parameters
    ----------
    pose : ndarray, shape (3,)
        The robot's world pose.
    mounts : ndarray, shape (M, 3)
        The sensors' poses on the robot.

    Returns
    -------
    ndarray, shape (M, 3)
    """
    c, s = np.cos(pose[2]), np.sin(pose[2])
    x = pose[0] + c * mounts[:, 0] - s * mounts[:, 1]
    y = pose[1] + s * mounts[:, 0] + c * mounts[:, 1]
    return np.column_stack([x, y, pose[2] + mounts[:, 2]])


def ring(
    walls: np.ndarray,
    pose: np.ndarray,
    mounts: np.ndarray,
    params: SonarParams,
    rng: np.random.Generator,
    discs: np.ndarray | None = None,
) -> np.ndarray:
    """One ring of readings (M,) from a robot at world ``pose`` (``discs``: people).

    Parameters
    ----------
    walls : ndarray, shape (S, 4)
        Wall segments.
    pose : ndarray, shape (3,)
        The robot's world pose.
    mounts : ndarray, shape (M, 3)
        The sensors' poses on the robot.
    params : SonarParams
        The sonar model.
    rng : numpy.random.Generator
        The sonar's random stream.
    discs : ndarray, shape (J, 3), optional
        People (x, y, radius).

    Returns
    -------
    ndarray, shape (M,)
        Readings (m).
    """
    return measure(ideal_ranges(walls, sensor_poses(pose, mounts), params, discs), params, rng)


def ideal_ranges_many(
    walls: np.ndarray,
    poses: np.ndarray,
    mounts: np.ndarray,
    params: SonarParams,
    discs: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`ideal_ranges` of K rings at once: every ray is traced on its own
    (element-wise operations and per-ray minima), so ring k's row is bit for bit
    ``ideal_ranges(walls, sensor_poses(poses[k], mounts), params, discs[k])``, with the
    numpy call overhead paid once for the K rings (tests/test_fast_paths.py).

    Parameters
    ----------
    walls : ndarray, shape (S, 4)
        Wall segments.
    poses : ndarray, shape (K, 3) or (K, M, 3)
        The robot's world poses: one per ring, or, for sonars fired in sequence, one per
        sonar as it fires (``poses[k, j]``).
    mounts : ndarray, shape (M, 3)
        The sensors' poses on the robot.
    params : SonarParams
        The sonar model.
    discs : ndarray, shape (K, J, 3) or (K, M, J, 3), optional
        The people (x, y, radius) each ring sees (the same J for every ring), or each
        sonar of it as it fires.

    Returns
    -------
    ndarray, shape (K, M)
        Ranges (m); inf: no echo.
    """
    k, m = len(poses), len(mounts)
    if poses.ndim == 3:  # sonar j of ring k at poses[k, j]
        sensors = compose(poses.reshape(-1, 3), np.tile(mounts, (k, 1)))
    else:
        sensors = np.concatenate([sensor_poses(p, mounts) for p in poses])
    if discs is not None:
        discs = np.asarray(discs, dtype=float)
        discs = (
            discs.reshape(k * m, *discs.shape[2:])
            if discs.ndim == 4
            else np.repeat(discs, m, axis=0)
        )
    return ideal_ranges(walls, sensors, params, discs).reshape(k, m)
