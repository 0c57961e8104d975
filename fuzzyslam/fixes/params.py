"""Parameters of heading and pose fixes from the frozen fuzzy map (models.md sec. 9-10)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class FixParams:
    """Heading fixes (the paper) and full-pose fixes (beyond it)."""

    mode: str = field(default="heading", metadata={"choices": ["none", "heading", "pose"]})
    sigma_heading_deg: float = field(default=1.0, metadata={"min": 0.01, "max": 90.0})
    gate_chi2: float = field(default=6.63, metadata={"min": 0.1})
