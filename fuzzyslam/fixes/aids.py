"""The thin edge of the fixes stage: load a frozen map directory and make ``run``'s aids.

``make_aids(fgm_dir, mode, cfg, start_time)`` is all ``fuzzyslam run --map`` needs:
it loads ``fgm.npz`` and ``references.yaml`` (contracts.md sec. 3), refuses a map that
is missing, malformed or was never frozen (one-line :class:`InputError`), and returns
the plug-ins for the chosen mode, sharing one FLM per ring:

- ``none``: no aids;
- ``heading``: :class:`HeadingFixAid` (the paper);
- ``pose``: :class:`PoseFixAid` and, with ``fixes.detect_changes``, :class:`ChangeDetector`.

Each aid has ``start_time``, ``on_ring(t, ring, mounts, ekf)``, ``summary()`` and
``write(outdir)``. ``start_time`` defaults to the map's freeze time.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import check_input_file
from fuzzyslam.fixes.changes import ChangeDetector
from fuzzyslam.fixes.heading import FlmSource, HeadingFixAid
from fuzzyslam.fixes.pose_match import PoseFixAid
from fuzzyslam.fixes.references import Reference, references_from_dicts
from fuzzyslam.maps.grid import BeliefMap, Grid

MODES = ("none", "heading", "pose")


@dataclass
class FrozenMap:
    """A frozen FGM with its corridor references, as ``run`` needs it."""

    fgm: BeliefMap
    freeze_time: float
    log_id: str
    references: list[Reference]


def load_fgm_npz(path: Path) -> tuple[BeliefMap, bool, float, str]:
    """(map, frozen, freeze_time, log_id) from fgm.npz; InputError naming the file if bad."""
    check_input_file(path, "fgm.npz")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise InputError(path, f"not a readable .npz map: {exc}") from None
    need = ("m_e", "m_o", "m_t", "m_c", "origin", "resolution", "frozen")
    missing = [k for k in need if k not in data]
    if missing:
        raise InputError(path, f"map is missing arrays: {', '.join(missing)}")
    masses = [np.asarray(data[k], dtype=np.float32) for k in ("m_e", "m_o", "m_t", "m_c")]
    shape = masses[0].shape
    if len(shape) != 2 or any(m.shape != shape for m in masses):
        raise InputError(path, "mass arrays must be 2-D and of one shape")
    if not all(np.all(np.isfinite(m)) for m in masses):
        raise InputError(path, "mass arrays hold NaN or infinite values")
    if not np.allclose(sum(masses), 1.0, atol=1e-3):
        raise InputError(path, "masses do not sum to 1 per cell")
    origin = np.asarray(data["origin"], dtype=float).reshape(-1)
    res = float(np.asarray(data["resolution"]).reshape(()))
    if origin.size != 2 or not np.all(np.isfinite(origin)) or not res > 0:
        raise InputError(path, "bad grid geometry (origin (2,), resolution > 0)")
    grid = Grid((float(origin[0]), float(origin[1])), res, (int(shape[0]), int(shape[1])))
    frozen = bool(np.asarray(data["frozen"]).reshape(()))
    ft = float(np.asarray(data.get("freeze_time", np.nan)).reshape(()))
    log_id = str(np.asarray(data.get("log_id", "")).reshape(()))
    return BeliefMap(grid, *masses), frozen, ft, log_id


def load_references(path: Path) -> list[Reference]:
    """Corridor references from references.yaml; InputError naming the file if bad."""
    check_input_file(path, "references.yaml")
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise InputError(path, f"cannot read references: {exc}".splitlines()[0]) from None
    if not isinstance(data, dict) or not isinstance(data.get("references"), list):
        raise InputError(path, "expected a mapping with a 'references' list")
    return references_from_dicts(data["references"], str(path))


def load_frozen_map(fgm_dir: Path) -> FrozenMap:
    """Load and check a map directory written by ``fuzzyslam map``."""
    fgm_dir = Path(fgm_dir)
    if not fgm_dir.is_dir():
        raise InputError(fgm_dir, "map directory does not exist")
    fgm, frozen, ft, log_id = load_fgm_npz(fgm_dir / "fgm.npz")
    if not frozen:
        raise InputError(fgm_dir / "fgm.npz", "the map was never frozen; fixes need a frozen map")
    if not np.isfinite(ft):
        raise InputError(fgm_dir / "fgm.npz", "the frozen map has no freeze_time")
    refs = load_references(fgm_dir / "references.yaml")
    return FrozenMap(fgm, ft, log_id, refs)


def make_aids(fgm_dir: Path, mode: str, cfg: Any, start_time: float | None = None) -> list[Any]:
    """The plug-ins of ``run`` for ``mode`` in none|heading|pose (module docstring)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
    if mode == "none":
        return []
    fm = load_frozen_map(Path(fgm_dir))
    return aids_for_map(fm, mode, cfg, start_time)


def aids_for_map(fm: FrozenMap, mode: str, cfg: Any, start_time: float | None = None) -> list:
    """The plug-ins for an already loaded map (pure: no I/O)."""
    from fuzzyslam.maps.flm import build_flm
    from fuzzyslam.maps.hough import flm_wall_direction

    t0 = fm.freeze_time if start_time is None else float(start_time)
    mp = cfg.fgm
    source = FlmSource(
        lambda ring, mounts: build_flm(ring.ranges, ring.max_range, ring.fov, mounts, mp)
    )
    if mode == "heading":
        if not fm.references:
            raise InputError("references.yaml", "no corridor references: heading fixes need some")
        return [
            HeadingFixAid(
                fm.references, cfg.fixes, source, lambda flm: flm_wall_direction(flm, mp), t0
            )
        ]
    aids: list[Any] = [PoseFixAid(fm.fgm, cfg.fixes, source, t0)]
    if cfg.fixes.detect_changes:
        aids.append(ChangeDetector(fm.fgm, cfg.fixes, source, t0))
    return aids
