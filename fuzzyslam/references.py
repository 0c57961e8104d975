"""Corridor references (docs/contracts.md sec. 3): the one :class:`Reference` type and the
one reader and writer of ``references.yaml``.

The map stage finds them (:func:`fuzzyslam.maps.references.extract_references`, angles in
[0, pi)) and writes them; the fixes read them back (angles wrapped to (-pi/2, pi/2], mod
pi as ever). ``references.yaml`` holds ``{frame, references: [{id, name, angle, angle_deg,
strength, ambiguous, cells, region}]}`` where ``region`` is a polygon ``[[x, y], ...]`` or
a bounding box (``[xmin, ymin, xmax, ymax]`` or ``{bbox: [...]}``).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fuzzyslam.errors import InputError
from fuzzyslam.fileio import atomic_path, check_input_file
from fuzzyslam.polygons import points_in_polygon
from fuzzyslam.se2 import wrap_angle_period


@dataclass(frozen=True, eq=False)  # compared and hashed by identity (it holds arrays)
class Reference:
    """One corridor: id, name, reference angle (rad, mod pi), Hough strength, region
    polygon (K, 2), whether the map stage found no single dominant direction; from the map
    stage also its wall cells, Hough result (``maps.hough.WallDirection``) and stretch
    (``maps.references.Stretch``)."""

    id: int
    name: str
    angle: float
    strength: float
    region: np.ndarray  # (K, 2), K >= 3
    ambiguous: bool = False
    cells: int = 0
    wall: Any = field(default=None, repr=False, compare=False)
    stretch: Any = field(default=None, repr=False, compare=False)

    @property
    def polygon(self) -> np.ndarray:
        """The region (K, 2)."""
        return self.region

    @cached_property
    def _box(self) -> tuple[float, float, float, float]:
        """The region's bounding box grown by 1 um: a point beyond it is outside (no edge
        straddles its y, or all cross on one side), so ``contains`` skips the test."""
        lo, hi = self.region.min(axis=0), self.region.max(axis=0)
        return float(lo[0]) - 1e-6, float(lo[1]) - 1e-6, float(hi[0]) + 1e-6, float(hi[1]) + 1e-6

    def contains(self, xy: Sequence[float]) -> bool:
        """Whether the point ``xy`` lies in the region (PNPOLY, after the box test)."""
        p = np.asarray(xy, float).reshape(1, 2)
        x0, y0, x1, y1 = self._box
        if not (x0 <= p[0, 0] <= x1 and y0 <= p[0, 1] <= y1):
            return False
        return bool(points_in_polygon(p, self.region)[0])

    def to_dict(self) -> dict:
        return {
            "id": int(self.id),
            "name": self.name,
            "angle": float(self.angle),
            "angle_deg": float(np.rad2deg(self.angle)),
            "strength": float(self.strength),
            "ambiguous": bool(self.ambiguous),
            "cells": int(self.cells),
            "region": [[float(x), float(y)] for x, y in self.region],
        }


def _region_polygon(region: Any, source: str, where: str) -> np.ndarray:
    if isinstance(region, dict):
        if "bbox" in region:
            region = region["bbox"]
        elif "polygon" in region:
            region = region["polygon"]
        else:
            raise InputError(source, f"{where}: region needs 'bbox' or 'polygon'")
    try:
        arr = np.asarray(region, dtype=float)
    except (TypeError, ValueError):
        raise InputError(source, f"{where}: region is not numeric") from None
    if arr.ndim == 1 and arr.size == 4:
        x0, y0, x1, y1 = arr
        if not (x1 > x0 and y1 > y0):
            raise InputError(source, f"{where}: bbox must be [xmin, ymin, xmax, ymax]")
        arr = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
        raise InputError(source, f"{where}: region must be a polygon of >= 3 [x, y] points")
    if not np.all(np.isfinite(arr)):
        raise InputError(source, f"{where}: region has non-finite coordinates")
    return arr


def references_from_dicts(items: Iterable[dict[str, Any]], source: str) -> list[Reference]:
    """Parse the ``references`` list of references.yaml; ``source`` names the file in errors."""
    out: list[Reference] = []
    for i, d in enumerate(items):
        where = f"references[{i}]"
        if not isinstance(d, dict):
            raise InputError(source, f"{where} must be a mapping")
        for key in ("angle", "region"):
            if key not in d:
                raise InputError(source, f"{where}: missing '{key}'")
        try:
            angle = float(d["angle"])
            strength = float(d.get("strength", 1.0))
            rid = int(d.get("id", i))
        except (TypeError, ValueError):
            raise InputError(source, f"{where}: id/angle/strength must be numbers") from None
        if not np.isfinite(angle):
            raise InputError(source, f"{where}: angle is not finite")
        poly = _region_polygon(d["region"], source, where)
        name = str(d.get("name", f"corridor{rid}"))
        amb = bool(d.get("ambiguous", False))
        out.append(
            Reference(rid, name, float(wrap_angle_period(angle, np.pi)), strength, poly, amb)
        )
    ids = [r.id for r in out]
    if len(set(ids)) != len(ids):
        raise InputError(source, "corridor ids are not unique")
    return out


def save_references(
    path: str | os.PathLike, refs: list[dict[str, Any]], frame: str = "map"
) -> None:
    """Write references.yaml: ``{frame, references: [{id, name, angle, angle_deg, strength,
    region}]}`` (angles in rad mod pi, [0, pi))."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(
            yaml.safe_dump({"frame": frame, "references": refs}, sort_keys=False),
            encoding="utf-8",
        )


def load_references(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Read references.yaml back (a list of dicts); InputError when malformed."""
    p = check_input_file(path, "references")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError):
        raise InputError(p, "not valid YAML") from None
    if not isinstance(data, dict) or not isinstance(data.get("references"), list):
        raise InputError(p, "expected a mapping with a 'references' list")
    for i, r in enumerate(data["references"]):
        if not isinstance(r, dict) or not {"id", "angle", "region"} <= set(r):
            raise InputError(p, f"reference {i} lacks id, angle or region")
    return data["references"]


def write_references(
    path: str | os.PathLike, refs: Iterable[Reference], frame: str = "map"
) -> None:
    """Write references.yaml of ``refs`` (:meth:`Reference.to_dict`)."""
    save_references(path, [r.to_dict() for r in refs], frame)


def read_references(path: str | os.PathLike) -> list[Reference]:
    """The references of a references.yaml (angles wrapped to (-pi/2, pi/2]); InputError
    naming the file when it is malformed."""
    return references_from_dicts(load_references(path), str(path))
