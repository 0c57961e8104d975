"""Parameters of the EKF-SLAM filter and the lamp detector (config section ``slam``)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class SlamParams:
    """EKF-SLAM on ceiling lamps (models.md sec. 2-4).

    Odometry noise per increment (Probabilistic Robotics, sec. 5.4, plus a
    random-walk term per metre that makes the model independent of the odometry
    rate, [ours]):

        var_trans = a1 dt^2 + a2 dr^2 + a5 |dt|
        var_rot   = a3 dr^2 + a4 dt^2 + a6 |dt|
    """

    # odometry motion model: a1..a6 of the docstring. a5, a6 are the random walks of the
    # simulated encoders measured against ground truth on quick.yaml (translation 2.5e-6
    # m^2/m, heading 6.1e-5 rad^2/m); a3 covers the 1 % wheel-base error on turns
    # (0.0016 rad of systematic error between two frames in a turn).
    alpha: list[float] = field(
        default_factory=lambda: [1e-4, 1e-4, 1e-3, 1e-4, 3e-6, 6.5e-5],
        metadata={"min": 0.0, "max": 100.0, "len": 6},
    )
    use_encoders: bool = True
    # start pose (x, y, theta) when the log carries none, and its standard deviation
    start_pose: list[float] = field(
        default_factory=lambda: [0.0, 0.0, 0.0], metadata={"min": -1e6, "max": 1e6, "len": 3}
    )
    start_sigma: list[float] = field(
        default_factory=lambda: [1e-3, 1e-3, 1e-3], metadata={"min": 1e-9, "max": 1e3, "len": 3}
    )
    # lamp detector
    threshold: int = field(default=200, metadata={"min": 1, "max": 255})
    min_area: int = field(default=4, metadata={"min": 1})
    max_area: int = field(default=2000, metadata={"min": 1})
    min_fill: float = field(default=0.5, metadata={"min": 0.0, "max": 1.0})
    max_aspect: float = field(default=2.0, metadata={"min": 1.0})
    border: int = field(default=1, metadata={"min": 0, "max": 100})
    # centroid standard deviation (px): measured 0.007 px on simulated frames against the
    # true projections; 0.02 leaves room for what the simulator does not model
    pixel_sigma: float = field(default=0.02, metadata={"min": 0.001, "max": 100.0})
    # standard deviation (m) of a detection given as a PoseArray point (logs without frames)
    detection_sigma: float = field(default=0.02, metadata={"min": 1e-4, "max": 10.0})
    # data association
    gate_chi2: float = field(default=9.21, metadata={"min": 0.1})
    new_lamp_chi2: float = field(default=40.0, metadata={"min": 0.1})
    tentative_hits: int = field(default=3, metadata={"min": 1})
    tentative_radius: float = field(default=0.3, metadata={"min": 0.01, "max": 10.0})
    tentative_timeout: float = field(default=2.0, metadata={"min": 0.0})
    # outputs: trajectory rows at least this far apart (s) between camera updates
    record_period: float = field(default=0.2, metadata={"min": 0.0})
    # /slam/landmarks MarkerArray period in estimates.mcap (s)
    landmarks_period: float = field(default=10.0, metadata={"min": 0.01})
