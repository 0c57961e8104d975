"""A 2-D pose graph and its least-squares solution (``run --live-map``'s loop closure,
docs/models.md sec. 10b).

Nodes are poses x_k = (x, y, theta); an edge (i, j) measures the pose of j in the frame
of i, z_ij, with the square root W of its information matrix (W^T W = Sigma^-1). Its
residual is

    e_ij = W ( [R(theta_i)^T (t_j - t_i) ; theta_j - theta_i] - z_ij ),   angle wrapped,

and the graph's solution minimises sum rho(|e_ij|^2) over the poses, the first held
fixed (the map's frame), by Gauss-Newton on the sparse normal equations with the Huber
weights of iteratively reweighted least squares (Grisetti, Kuemmerle, Stachniss and
Burgard, "A tutorial on graph-based SLAM", IEEE ITS Magazine 2010, sec. IV; Huber 1964
for the robust weights, so that one false loop edge cannot bend the map).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from fuzzyslam.se2 import wrap_angle


def edge_errors(poses: np.ndarray, i: np.ndarray, j: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The unweighted errors [R_i^T (t_j - t_i); theta_j - theta_i] - z_ij (wrapped).

    Parameters
    ----------
    poses : ndarray, shape (N, 3)
        The nodes.
    i, j : ndarray of int, shape (E,)
        Each edge's nodes.
    z : ndarray, shape (E, 3)
        Each edge's measurement: the pose of j in the frame of i.

    Returns
    -------
    ndarray, shape (E, 3)
    """
    a, b = poses[i], poses[j]
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    e = np.stack([c * dx + s * dy - z[:, 0], -s * dx + c * dy - z[:, 1],
                  b[:, 2] - a[:, 2] - z[:, 2]], axis=1)  # fmt: skip
    e[:, 2] = wrap_angle(e[:, 2])
    return e


def edge_jacobians(
    poses: np.ndarray, i: np.ndarray, j: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """d e_ij / d x_i and d e_ij / d x_j of :func:`edge_errors`, analytically.

    Parameters
    ----------
    poses : ndarray, shape (N, 3)
        The nodes.
    i, j : ndarray of int, shape (E,)
        Each edge's nodes.

    Returns
    -------
    a, b : ndarray, shape (E, 3, 3)
        The Jacobians with respect to x_i and x_j.
    """
    p, q = poses[i], poses[j]
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    dx, dy = q[:, 0] - p[:, 0], q[:, 1] - p[:, 1]
    n = len(i)
    a = np.zeros((n, 3, 3))
    b = np.zeros((n, 3, 3))
    # R_i^T = [[c, s], [-s, c]]: d/d t_i = -R_i^T, d/d t_j = R_i^T
    a[:, 0, 0], a[:, 0, 1], a[:, 1, 0], a[:, 1, 1] = -c, -s, s, -c
    b[:, 0, 0], b[:, 0, 1], b[:, 1, 0], b[:, 1, 1] = c, s, -s, c
    # d(R_i^T d)/d theta_i = [[-s, c], [-c, -s]] d
    a[:, 0, 2] = -s * dx + c * dy
    a[:, 1, 2] = -c * dx - s * dy
    a[:, 2, 2] = -1.0
    b[:, 2, 2] = 1.0
    return a, b


def optimise(
    poses: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    z: np.ndarray,
    w: np.ndarray,
    huber: float = 3.0,
    iterations: int = 20,
    tol: float = 1e-8,
) -> tuple[np.ndarray, dict]:
    """The graph's poses minimising sum rho(|W e|^2), the first pose held fixed
    (module docstring): Gauss-Newton with Huber weights (IRLS).

    Parameters
    ----------
    poses : ndarray, shape (N, 3)
        The initial poses (the first is kept).
    i, j : ndarray of int, shape (E,)
        Each edge's nodes.
    z : ndarray, shape (E, 3)
        Each edge's measurement.
    w : ndarray, shape (E, 3, 3)
        Each edge's square-root information.
    huber : float
        The Huber threshold on |W e| (in sigmas): edges beyond it are down-weighted by
        huber / |W e|.
    iterations : int
        The most Gauss-Newton steps.
    tol : float
        Stop when the largest step is below this.

    Returns
    -------
    poses : ndarray, shape (N, 3)
        The solution (headings wrapped).
    info : dict
        ``iterations``, ``cost`` (sum of the robust costs) at the start and end,
        ``downweighted`` (edges beyond the Huber threshold at the end).
    """
    x = np.array(poses, dtype=float)
    i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
    z, w = np.asarray(z, dtype=float), np.asarray(w, dtype=float)
    n, m = len(x), len(i)
    rows = np.repeat(np.arange(3 * m).reshape(m, 3, 1), 3, axis=2)  # (E, 3, 3)

    def robust(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        r = np.einsum("eab,eb->ea", w, edge_errors(x, i, j, z))
        norm = np.sqrt(np.sum(r * r, axis=1))
        k = np.where(norm <= huber, 1.0, huber / np.maximum(norm, 1e-12))
        cost = np.where(norm <= huber, norm**2, 2 * huber * norm - huber**2)
        return r, k, float(cost.sum())

    _, _, cost0 = robust(x)
    done = 0
    for done in range(1, iterations + 1):  # noqa: B007 (the count is reported)
        r, k, _ = robust(x)
        ja, jb = edge_jacobians(x, i, j)
        sk = np.sqrt(k)[:, None, None]
        wa, wb = sk * (w @ ja), sk * (w @ jb)
        cols_a = (3 * i)[:, None, None] + np.arange(3)[None, None, :]
        cols_b = (3 * j)[:, None, None] + np.arange(3)[None, None, :]
        jac = sp.csr_matrix(
            (np.concatenate([wa.ravel(), wb.ravel()]),
             (np.concatenate([rows.ravel(), rows.ravel()]),
              np.concatenate([np.broadcast_to(cols_a, wa.shape).ravel(),
                              np.broadcast_to(cols_b, wb.shape).ravel()]))),
            shape=(3 * m, 3 * n),
        )  # fmt: skip
        jac = jac[:, 3:]  # the first pose is fixed
        rr = (np.sqrt(k)[:, None] * r).ravel()
        h = (jac.T @ jac).tocsc()
        g = jac.T @ rr
        step = spsolve(h + sp.identity(h.shape[0], format="csc") * 1e-9, -g)
        x[1:] += step.reshape(-1, 3)
        x[:, 2] = wrap_angle(x[:, 2])
        if float(np.max(np.abs(step), initial=0.0)) < tol:
            break
    r, k, cost = robust(x)
    return x, {"iterations": done, "cost_start": cost0, "cost": cost,
               "downweighted": int(np.count_nonzero(k < 1.0))}  # fmt: skip
