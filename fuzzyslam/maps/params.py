"""Parameters of the fuzzy global and local maps (models.md sec. 5-8)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class MapParams:
    """Fuzzy grid maps from sonar evidence, Smets' calculus and forgetting."""

    resolution: float = field(default=0.10, metadata={"min": 0.01, "max": 1.0})
    margin: float = field(default=1.0, metadata={"min": 0.0, "max": 20.0})
    flm_cells: int = field(default=41, metadata={"min": 5, "max": 1001})
    freeze_run: int = field(default=4, metadata={"min": 1})
    k_occupied: float = field(default=0.6, metadata={"min": 0.0, "max": 1.0})
    k_empty: float = field(default=0.4, metadata={"min": 0.0, "max": 1.0})
    range_tolerance: float = field(default=0.10, metadata={"min": 0.01, "max": 2.0})
    forgetting_gamma: float = field(default=1.0, metadata={"min": 0.0, "max": 1.0})
