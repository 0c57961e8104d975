"""Parameters of the evaluation."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class EvalParams:
    """How estimates are paired with truth and errors summarised."""

    # relative pose error over this much true travel (m), reported per metre
    rpe_delta_m: float = field(default=1.0, metadata={"min": 0.01, "max": 1000.0})
    # an estimate sample is compared only if a truth sample lies within this time (s)
    max_dt_s: float = field(default=0.1, metadata={"min": 1e-6, "max": 10.0})
    # an estimated lamp farther than this from every true lamp is never matched to one (m)
    lamp_max_dist_m: float = field(default=0.5, metadata={"min": 0.01, "max": 100.0})
