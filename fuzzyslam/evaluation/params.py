"""Parameters of the evaluation."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class EvalParams:
    """How estimates are paired with truth and errors summarised.

    The truth is interpolated at each estimate stamp between the two truth samples around
    it when they are at most ``max_gap_s`` apart, or when one lies within ``max_dt_s``
    (:func:`fuzzyslam.evaluation.metrics.associate`). ``max_gap_s`` = 0.5 s is a bound
    on the robot's motion, not on any file's rate: a straight line between two samples g
    seconds apart departs from a path of acceleration a by at most a g^2 / 8, which for an
    indoor wheeled robot (a <= 1 m/s^2, angular acceleration <= 2 rad/s^2) is 3 cm and
    4 deg at 0.5 s, the size of a scan-matched truth's own error, and four times that at
    1 s. So a 4-6 Hz scan-matched truth (0.15-0.3 s apart, 0.5 s where a stray line was
    dropped) is compared all along, and a longer gap is left out rather than a truth
    invented across it. (Thinning the MRCLAM Vicon truth to 0.5 s and interpolating it
    back errs by 2.4 mm and 1.5 deg at the 95th percentile, 1.0 s by 4.3 mm and 2.7 deg,
    up to 10 deg.)
    """

    # relative pose error over this much true travel (m), reported per metre
    rpe_delta_m: float = field(default=1.0, metadata={"min": 0.01, "max": 1000.0})
    # an estimate sample is compared if a truth sample lies within this time (s) ...
    max_dt_s: float = field(default=0.1, metadata={"min": 1e-6, "max": 10.0})
    # ... or if the truth samples around it are at most this far apart (s): interpolated
    max_gap_s: float = field(default=0.5, metadata={"min": 0.0, "max": 10.0})
    # an estimated lamp farther than this from every true lamp is never matched to one (m)
    lamp_max_dist_m: float = field(default=0.5, metadata={"min": 0.01, "max": 100.0})
