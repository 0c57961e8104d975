"""Map files (docs/contracts.md sec. 3): fgm.npz, nav2 map_server fgm.yaml + fgm.pgm,
references.yaml (its reader and writer: :mod:`fuzzyslam.references`). Every file is written
to a temporary name and renamed when complete.

nav2 map_server (``nav2_map_server``, map_io): with ``negate: 0`` a pixel p in 0..255
has occupancy (255 - p) / 255; ``mode: trinary`` makes it occupied above
``occupied_thresh``, free below ``free_thresh``, unknown between. The image's top row is
the map's largest y; ``origin`` is the pose of the lower-left pixel [x, y, yaw].
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import atomic_path, check_input_file
from fuzzyslam.maps.grid import MAX_CELLS, BeliefMap, Grid

# references.yaml's reader and writer live in fuzzyslam/references.py (re-exported)
from fuzzyslam.references import load_references as load_references
from fuzzyslam.references import save_references as save_references

OCCUPIED_THRESH = 0.65
FREE_THRESH = 0.196
PGM_OCCUPIED, PGM_FREE, PGM_UNKNOWN = 0, 254, 205
NPZ_KEYS = ("m_e", "m_o", "m_t", "m_c", "origin", "resolution", "shape", "frozen", "freeze_time")
MASSES = ("m_e", "m_o", "m_t", "m_c")
# what a map may be: cells of 1 mm to 10 m, an origin within 1000 km, at most MAX_CELLS
MIN_RESOLUTION, MAX_RESOLUTION = 1e-3, 10.0
MAX_COORDINATE = 1e6


@dataclass
class FgmFile:
    """Contents of fgm.npz: the map, whether it is frozen, freeze time (s), log identity."""

    map: BeliefMap
    frozen: bool
    freeze_time: float
    log_id: str


def log_identity(world: dict[str, Any] | None, fallback: str = "") -> str:
    """Identity of the world a log was recorded in: ``world-`` + 16 hex digits of the
    SHA-256 of its canonical JSON (a simulated log: every log of that world has it); for
    logs without a world record (real robots), ``log-`` + the hash of ``fallback``, the
    recording's own fingerprint (``LogReader.fingerprint``: a copy under another name
    has the same, another recording does not). ``run --map`` compares it with its log's.

    Parameters
    ----------
    world : dict or None
        The log's world record.
    fallback : str
        Used without a world: the log's fingerprint.

    Returns
    -------
    str
    """
    if world is not None:
        text = json.dumps(world, sort_keys=True, separators=(",", ":"))
        return "world-" + hashlib.sha256(text.encode()).hexdigest()[:16]
    return "log-" + hashlib.sha256(fallback.encode()).hexdigest()[:16]


def grid_problem(origin: Any, resolution: Any, shape: Any) -> str | None:
    """Why a map's geometry is unusable (None if it is fine): resolution finite within
    [MIN_RESOLUTION, MAX_RESOLUTION], origin two finite numbers within MAX_COORDINATE,
    shape two positive integers of at most MAX_CELLS cells together.

    Parameters
    ----------
    origin : Any
        (x, y) of the grid's corner (m).
    resolution : Any
        Cell size (m).
    shape : Any
        (ny, nx).

    Returns
    -------
    str or None
    """
    res = np.asarray(resolution, dtype=float)
    org = np.asarray(origin, dtype=float)
    shp = np.asarray(shape)
    if res.shape != () or not np.isfinite(res) or not MIN_RESOLUTION <= res <= MAX_RESOLUTION:
        return (
            f"resolution must be a finite number of metres in [{MIN_RESOLUTION:g}, "
            f"{MAX_RESOLUTION:g}], got {np.array2string(res.ravel()[:2])}"
        )
    if org.shape != (2,) or not np.all(np.isfinite(org)) or np.any(np.abs(org) > MAX_COORDINATE):
        return f"origin must be two finite coordinates within {MAX_COORDINATE:g} m"
    if shp.shape != (2,) or shp.dtype.kind not in "iu" or np.any(shp < 1):
        return "shape must be two positive integers"
    if int(shp[0]) * int(shp[1]) > MAX_CELLS:
        return f"{int(shp[0])} x {int(shp[1])} cells, more than {MAX_CELLS}"
    return None


def fgm_problem(bm: BeliefMap, frozen: bool, freeze_time: float) -> str | None:
    """Why a map is unusable (None if it is fine): its geometry, masses that are not
    finite numbers in [0, 1], a frozen map without a finite freeze time.

    Parameters
    ----------
    bm : BeliefMap
        The FGM (masses (ny, nx)).
    frozen : bool
        Whether the map is frozen.
    freeze_time : float
        Its freeze time (s).

    Returns
    -------
    str or None
    """
    g = bm.grid
    problem = grid_problem(g.origin, g.resolution, g.shape)
    if problem:
        return problem
    for name in MASSES:
        a = getattr(bm, name)
        if a.shape != tuple(g.shape):
            return f"mass arrays do not match the grid shape {tuple(g.shape)}"
        if not np.all(np.isfinite(a)) or a.min(initial=0.0) < -1e-3 or a.max(initial=0.0) > 1.001:
            return f"{name} must hold finite masses in [0, 1]"
    if frozen and not np.isfinite(freeze_time):
        return "the frozen map has no finite freeze_time"
    return None


def save_fgm(
    path: str | os.PathLike, bm: BeliefMap, frozen: bool, freeze_time: float, log_id: str
) -> None:
    """Write fgm.npz (masses float32 (ny, nx), grid geometry, freeze state, log_id);
    a map that ``load_fgm`` would refuse is not written (InputError naming ``path``).

    Parameters
    ----------
    path : path
        fgm.npz.
    bm : BeliefMap
        The FGM (masses (ny, nx)).
    frozen : bool
        Whether the map is frozen.
    freeze_time : float
        Its freeze time (s).
    log_id : str
        :func:`log_identity` of its log.
    """
    problem = fgm_problem(bm, frozen, freeze_time)
    if problem:
        raise InputError(path, f"refusing to write an unusable map: {problem}")
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(
            f,
            m_e=bm.m_e.astype(np.float32),
            m_o=bm.m_o.astype(np.float32),
            m_t=bm.m_t.astype(np.float32),
            m_c=bm.m_c.astype(np.float32),
            origin=np.asarray(bm.grid.origin, dtype=float),
            resolution=np.float64(bm.grid.resolution),
            shape=np.asarray(bm.grid.shape, dtype=np.int64),
            frozen=np.bool_(frozen),
            freeze_time=np.float64(freeze_time),
            log_id=np.str_(log_id),
        )


def load_fgm(path: str | os.PathLike) -> FgmFile:
    """Read fgm.npz; a missing key or inconsistent shape is an InputError naming the file.

    Parameters
    ----------
    path : path
        fgm.npz.

    Returns
    -------
    FgmFile
    """
    p = check_input_file(path, "fuzzy map")
    try:
        with np.load(p, allow_pickle=False) as z:
            missing = [k for k in NPZ_KEYS if k not in z.files]
            if missing:
                raise InputError(p, f"not an FGM file: missing {', '.join(missing)}")
            problem = grid_problem(z["origin"], z["resolution"], z["shape"])
            if problem:
                raise InputError(p, f"damaged map: {problem}")
            shape = tuple(int(v) for v in z["shape"])
            grid = Grid(tuple(float(v) for v in z["origin"]), float(z["resolution"]), shape)
            for k in MASSES:  # the declared array shapes, before anything is allocated
                if _npz_member_shape(p, k) != shape:
                    raise InputError(p, f"mass arrays do not match the grid shape {shape}")
            arrs = [np.asarray(z[k], dtype=np.float32) for k in MASSES]
            frozen = bool(z["frozen"])
            freeze_time = float(z["freeze_time"])
            log_id = str(z["log_id"]) if "log_id" in z.files else ""
    except InputError:
        raise
    except Exception as exc:  # zip/npy format errors
        raise InputError(p, f"not a readable .npz map ({type(exc).__name__})") from None
    bm = BeliefMap(grid, *arrs)
    problem = fgm_problem(bm, frozen, freeze_time)
    if problem:
        raise InputError(p, f"damaged map: {problem}")
    return FgmFile(bm, frozen, freeze_time, log_id)


def _npz_member_shape(path: Path, key: str) -> tuple[int, ...] | None:
    """The shape an .npz member's header declares (read without loading the array)."""
    with zipfile.ZipFile(path) as zf, zf.open(f"{key}.npy") as f:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, _, _ = np.lib.format.read_array_header_1_0(f)
        elif version == (2, 0):
            shape, _, _ = np.lib.format.read_array_header_2_0(f)
        else:
            return None
    return tuple(int(v) for v in shape)


def occupancy_image(bm: BeliefMap, unknown_t: float = 0.9) -> np.ndarray:
    """Trinary PGM pixels (ny, nx), top row = max y: occupied where BetP(O) > 0.65, free
    where BetP(O) < 0.196, unknown where nothing is known (m(T) > ``unknown_t``) or between.

    Parameters
    ----------
    bm : BeliefMap
        The FGM (masses (ny, nx)).
    unknown_t : float
        m(Theta) above which a cell is unknown.

    Returns
    -------
    ndarray of uint8, shape (ny, nx)
    """
    betp = bm.pignistic_occupied()
    img = np.full(bm.grid.shape, PGM_UNKNOWN, dtype=np.uint8)
    known = bm.m_t <= unknown_t
    img[known & (betp > OCCUPIED_THRESH)] = PGM_OCCUPIED
    img[known & (betp < FREE_THRESH)] = PGM_FREE
    return np.flipud(img)


def _nav2_metres(v: float) -> float:
    """``v`` (m) rounded to 1e-9 m, so that fgm.yaml shows -25.7, not the float noise of
    the grid's arithmetic (-25.700000000000003); still a plain YAML float for nav2, and
    never -0.0."""
    return round(float(v), 9) + 0.0


def save_nav2(yaml_path: str | os.PathLike, pgm_path: str | os.PathLike, bm: BeliefMap) -> None:
    """Write the nav2 map_server pair (binary PGM P5 + YAML naming it).

    Parameters
    ----------
    yaml_path : path
        fgm.yaml.
    pgm_path : path
        fgm.pgm.
    bm : BeliefMap
        The FGM (masses (ny, nx)).
    """
    img = occupancy_image(bm)
    ny, nx = img.shape
    with atomic_path(pgm_path) as tmp:
        Path(tmp).write_bytes(f"P5\n{nx} {ny}\n255\n".encode() + img.tobytes())
    meta = {
        "image": Path(pgm_path).name,
        "mode": "trinary",
        "resolution": _nav2_metres(bm.grid.resolution),
        "origin": [_nav2_metres(bm.grid.origin[0]), _nav2_metres(bm.grid.origin[1]), 0.0],
        "negate": 0,
        "occupied_thresh": OCCUPIED_THRESH,
        "free_thresh": FREE_THRESH,
    }
    with atomic_path(yaml_path) as tmp:
        Path(tmp).write_text(yaml.safe_dump(meta, sort_keys=False), encoding="utf-8")


def read_pgm(path: str | os.PathLike) -> np.ndarray:
    """Read a binary (P5, 8-bit) PGM written by :func:`save_nav2`.

    Parameters
    ----------
    path : path
        The PGM.

    Returns
    -------
    ndarray of uint8, shape (H, W)
    """
    p = check_input_file(path, "PGM image")
    data = p.read_bytes()
    parts = data.split(maxsplit=4)
    if len(parts) < 5 or parts[0] != b"P5" or parts[3] != b"255":
        raise InputError(p, "not an 8-bit binary PGM (P5)")
    nx, ny = int(parts[1]), int(parts[2])
    body = parts[4]
    if len(body) != nx * ny:
        raise InputError(p, f"PGM holds {len(body)} bytes, expected {nx * ny}")
    return np.frombuffer(body, dtype=np.uint8).reshape(ny, nx)
