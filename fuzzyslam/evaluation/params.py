"""Parameters of the evaluation."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class EvalParams:
    """How errors are summarised."""

    rpe_delta_m: float = field(default=1.0, metadata={"min": 0.01, "max": 1000.0})
