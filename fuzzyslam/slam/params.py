"""Parameters of the EKF-SLAM filter and the lamp detector."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class SlamParams:
    """EKF-SLAM on ceiling lamps (models.md sec. 2-4)."""

    # odometry motion model (Probabilistic Robotics): var_trans = a1 dt^2 + a2 dr^2, ...
    alpha: list[float] = field(default_factory=lambda: [0.02, 0.001, 0.02, 0.001])
    # lamp detector
    threshold: int = field(default=200, metadata={"min": 1, "max": 255})
    min_area: int = field(default=4, metadata={"min": 1})
    max_area: int = field(default=2000, metadata={"min": 1})
    pixel_sigma: float = field(default=0.5, metadata={"min": 0.01, "max": 100.0})
    # data association
    gate_chi2: float = field(default=9.21, metadata={"min": 0.1})
    new_lamp_chi2: float = field(default=40.0, metadata={"min": 0.1})
    tentative_hits: int = field(default=3, metadata={"min": 1})
    use_encoders: bool = True
