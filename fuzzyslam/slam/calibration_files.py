"""The odometry self-calibration's files (slam/calibration.py; docs/contracts.md): one
reader and one writer per format.

- calibration.csv (``run``): a row per second at most, t, the factors, their sigmas and
  correlations (:func:`csv_header`, :func:`csv_row`, :func:`write_csv`); read back at
  a time by :func:`at_time` (the map stage: the calibration at its freeze time);
- calibration.yaml (``run``, ``map``): the factors and covariance (:func:`as_dict`,
  :func:`write_yaml`); read by :func:`load` (``run --calibration``).
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import numpy as np
import yaml

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import check_input_file
from fuzzyslam.slam.calibration import NAMES, Calibration
from fuzzyslam.stamps import format_time


def csv_header(model: Calibration) -> list[str]:
    """calibration.csv's header: t, the factors, their sigmas, their correlations.

    Parameters
    ----------
    model : Calibration
        The calibration model (kind, names).

    Returns
    -------
    list of str
    """
    names = model.names
    corr = [f"corr_{a}_{b}" for i, a in enumerate(names) for b in names[i + 1 :]]
    return ["t", *names, *(f"sigma_{n}" for n in names), *corr]


def csv_row(t: float, c: np.ndarray, cov: np.ndarray) -> list[str]:
    """One calibration.csv row: t (9 decimals), factors, sigmas, correlations.

    Parameters
    ----------
    t : float
        Log time (s).
    c : ndarray, shape (k,)
        The factors.
    cov : ndarray, shape (k, k)
        Their covariance.

    Returns
    -------
    list of str
    """
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0))
    k = len(c)
    corr = [
        cov[i, j] / (sig[i] * sig[j]) if sig[i] * sig[j] > 0 else 0.0
        for i in range(k)
        for j in range(i + 1, k)
    ]
    return [format_time(t), *(f"{v:.9g}" for v in (*c, *sig, *corr))]


def write_csv(path: Path, model: Calibration, rows: list[list[str]]) -> None:
    """calibration.csv: :func:`csv_header` and ``rows`` (:func:`csv_row`), into a staging
    directory.

    Parameters
    ----------
    path : Path
        The file to write (in an ``OutputDir``'s staging directory).
    model : Calibration
        The calibration model (its factors' names).
    rows : list of list of str
        The rows, each t, k factors, k sigmas, k (k - 1) / 2 correlations.
    """
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(csv_header(model))
    w.writerows(rows)
    path.write_text(buf.getvalue())  # into an OutputDir's staging directory


def as_dict(model: Calibration, t: float | None, c: np.ndarray, cov: np.ndarray) -> dict:
    """calibration.yaml's content.

    Parameters
    ----------
    model : Calibration
        The calibration model (kind, names).
    t : float or None
        The time the factors hold at (s).
    c : ndarray, shape (k,)
        The factors.
    cov : ndarray, shape (k, k)
        Their covariance.

    Returns
    -------
    dict
        model, names, factors, sigma, covariance[, wheel_base_nominal][, t].
    """
    sig = np.sqrt(np.maximum(np.diag(cov), 0.0))
    out = {
        "model": model.kind,
        "names": list(model.names),
        "factors": [float(v) for v in c],
        "sigma": [float(v) for v in sig],
        "covariance": [[float(v) for v in row] for row in cov],
    }
    if model.kind == "wheels":
        out["wheel_base_nominal"] = float(model.wheel_base)
    if t is not None:
        out["t"] = float(t)
    return out


def write_yaml(path: Path, d: dict) -> None:
    """calibration.yaml of ``d`` (:func:`as_dict`), into a staging directory.

    Parameters
    ----------
    path : Path
        The file to write (in an ``OutputDir``'s or the map stage's staging directory).
    d : dict
        The content (:func:`as_dict` or :func:`at_time`), keys in that order.
    """
    path.write_text(yaml.safe_dump(d, sort_keys=False))  # staged, as write_csv


NOT_CALIBRATION_YAML = (
    "not a calibration.yaml (a run's or a map's: model, factors and covariance); a run's "
    "calibration.csv is the input of 'map --calibration', not of 'run --calibration'"
)


def load(path: str | Path, model: Calibration) -> Calibration:
    """``model`` started from the factors and covariance of a calibration.yaml (a run's,
    or a map directory's: the calibration at the map's freeze time).

    Parameters
    ----------
    path : path
        A calibration.yaml.
    model : Calibration
        The calibration model (kind, names).

    Returns
    -------
    Calibration
        ``model`` with the file's factors and covariance (InputError naming the file).
    """
    path = check_input_file(path, "calibration")  # an input: never replaced by an output
    try:
        d = yaml.safe_load(path.read_text())
    except (UnicodeDecodeError, yaml.YAMLError):
        d = None
    if not isinstance(d, dict) or not {"model", "factors", "covariance"} <= d.keys():
        # e.g. a run's calibration.csv (map's input), read by YAML as one string
        raise InputError(path, NOT_CALIBRATION_YAML)
    kind = d["model"]
    if kind != model.kind:
        raise InputError(
            path, f"calibration model '{kind}', but this log's odometry needs '{model.kind}'"
        )
    k = model.k
    try:
        c = np.asarray(d["factors"], dtype=float)
        cov = np.asarray(d["covariance"], dtype=float)
    except (TypeError, ValueError):
        c = cov = np.zeros(0)  # not numbers: refused below
    ok = c.shape == (k,) and cov.shape == (k, k) and np.all(np.isfinite(cov))
    if not ok or not np.all(np.isfinite(c)) or np.any(c <= 0):
        raise InputError(path, f"needs {k} positive factors and a {k}x{k} covariance")
    if np.linalg.eigvalsh(0.5 * (cov + cov.T)).min() <= 0:
        raise InputError(path, "the covariance is not positive definite")
    return Calibration(
        kind, model.wheel_base, c, 0.5 * (cov + cov.T), model.var_per_m, model.var_per_rad,
        str(path),
    )  # fmt: skip


def at_time(csv_path: Path, t_end: float) -> dict | None:
    """The calibration of a run's calibration.csv at time ``t_end`` (its last row at or
    before it) as a calibration.yaml dict; None without the file or such a row.

    Parameters
    ----------
    csv_path : Path
        A run's calibration.csv.
    t_end : float
        The time (s).

    Returns
    -------
    dict or None
    """
    if not csv_path.is_file():
        return None
    check_input_file(csv_path, "calibration")  # an input: never replaced by an output
    with csv_path.open(newline="") as f:
        rows = list(csv.reader(f))
    if len(rows) < 2:
        return None
    head = rows[0]
    k = (math.isqrt(8 * (len(head) - 1) + 9) - 3) // 2  # 1 + 2k + k(k-1)/2 columns
    names = tuple(head[1 : 1 + k])
    kind = next((m for m, n in NAMES.items() if n == names), None)
    best = [r for r in rows[1:] if float(r[0]) <= t_end]
    if kind is None or not best:
        return None
    r = [float(v) for v in best[-1]]
    c, sig, corr = np.array(r[1 : 1 + k]), np.array(r[1 + k : 1 + 2 * k]), r[1 + 2 * k :]
    cm = np.eye(k)
    iu = np.triu_indices(k, 1)
    cm[iu] = corr
    cm.T[iu] = corr
    cov = cm * np.outer(sig, sig)
    model = Calibration(kind, 0.0, c, cov)
    d = as_dict(model, r[0], c, cov)
    d.pop("wheel_base_nominal", None)
    return d
