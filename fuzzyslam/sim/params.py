"""Parameters of the simulated world, robot, sensors and scenario (owned by the simulator)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class WorldParams:
    """The office floor: a loop of corridors around a centre line, and its ceiling lamps.

    Walls are the centre-line loop offset by +-corridor_width/2 (mitred corners). Lamps
    are placed evenly along the centre line (``lamp_count``, the first half a spacing
    from the first vertex) unless ``lamps`` lists them explicitly as [x, y].
    """

    centerline: list[list[float]] = field(
        default_factory=lambda: [[0.0, 0.0], [10.0, 0.0], [12.5, 7.0], [0.0, 7.0]],
        metadata={"min": -1e4, "max": 1e4, "item_len": 2},
    )
    corridor_width: float = field(default=2.0, metadata={"min": 1.0, "max": 10.0})
    lamps: list[list[float]] = field(
        default_factory=list, metadata={"min": -1e4, "max": 1e4, "item_len": 2, "max_items": 10000}
    )
    lamp_count: int = field(default=15, metadata={"min": 0, "max": 10000})
    lamp_radius: float = field(default=0.12, metadata={"min": 0.01, "max": 1.0})


@dataclass
class RobotParams:
    """Nomad 200-like base with wheel encoders (nominal values are what the filter knows)."""

    radius: float = field(default=0.225, metadata={"min": 0.05, "max": 2.0})
    wheel_radius: float = field(default=0.05, metadata={"min": 0.005, "max": 1.0})
    wheel_base: float = field(default=0.40, metadata={"min": 0.05, "max": 5.0})
    max_speed: float = field(default=0.5, metadata={"min": 0.01, "max": 5.0})
    cruise_speed: float = field(default=0.3, metadata={"min": 0.01, "max": 5.0})
    max_turn_rate: float = field(default=0.8, metadata={"min": 0.01, "max": 10.0})
    lookahead: float = field(default=0.8, metadata={"min": 0.05, "max": 10.0})
    # the driver's aim wanders sideways off the centre line (Ornstein-Uhlenbeck: std, time
    # constant), so the true path differs from seed to seed
    path_wander: float = field(default=0.1, metadata={"min": 0.0, "max": 1.0})
    wander_time: float = field(default=8.0, metadata={"min": 0.1, "max": 1000.0})
    rate_hz: float = field(default=20.0, metadata={"min": 1.0, "max": 1000.0})
    # systematic encoder errors: true wheel radius = nominal * scale, true base = nominal * scale
    left_scale: float = field(default=1.0004, metadata={"min": 0.5, "max": 1.5})
    right_scale: float = field(default=0.9996, metadata={"min": 0.5, "max": 1.5})
    base_scale: float = field(default=1.01, metadata={"min": 0.5, "max": 1.5})
    # random encoder error: std (rad) of a wheel's angle increment per sqrt(rad) turned
    wheel_noise: float = field(
        default=0.01, metadata={"min": 0.0, "max": 1.0, "unit": "rad/sqrt(rad)"}
    )
    ticks_per_rev: int = field(default=4096, metadata={"min": 1})
    # the wheels' joints in sensor_msgs/JointState (ros2_control names them after the
    # URDF: left_wheel_joint, ...); the simulator writes these, the filter reads them
    left_wheel_joint: str = "wheel_left_joint"
    right_wheel_joint: str = "wheel_right_joint"

    @property
    def wheel_joints(self) -> tuple[str, str]:
        """The left and right wheels' joint names."""
        return (self.left_wheel_joint, self.right_wheel_joint)


@dataclass
class SonarParams:
    """Ring of Polaroid-like sonars (docs/models.md sec. 11)."""

    count: int = field(default=16, metadata={"min": 1, "max": 64})
    rate_hz: float = field(default=4.0, metadata={"min": 0.1, "max": 100.0})
    fov_deg: float = field(default=25.0, metadata={"min": 1.0, "max": 90.0})
    min_range: float = field(default=0.15, metadata={"min": 0.0, "max": 10.0})
    max_range: float = field(default=6.5, metadata={"min": 0.5, "max": 50.0})
    noise_frac: float = field(default=0.01, metadata={"min": 0.0, "max": 0.5})
    quantization: float = field(default=0.0254, metadata={"min": 0.0, "max": 1.0})
    critical_angle_deg: float = field(default=17.0, metadata={"min": 1.0, "max": 90.0})
    # a reflected ray heading back within this angle of the sensor returns (corner reflector)
    return_angle_deg: float = field(default=12.5, metadata={"min": 0.0, "max": 90.0})
    rays_per_cone: int = field(default=9, metadata={"min": 1, "max": 101})
    max_bounces: int = field(default=2, metadata={"min": 0, "max": 5})
    crosstalk_prob: float = field(default=0.01, metadata={"min": 0.0, "max": 1.0})
    mount_height: float = field(default=0.5, metadata={"min": 0.0, "max": 5.0})
    # time between consecutive sonars of a ring (s): 0, the whole ring at once; a Pioneer's
    # ring fires its sonars one after another, about 40 ms apart. Each reading is taken
    # from the robot's pose at its own firing time and stamped with it
    firing_gap_s: float = field(default=0.0, metadata={"min": 0.0, "max": 0.5})


@dataclass
class CameraParams:
    """Upward ceiling camera (shared by the simulator and the lamp detector)."""

    width: int = field(default=160, metadata={"min": 16, "max": 4096})
    height: int = field(default=120, metadata={"min": 16, "max": 4096})
    rate_hz: float = field(default=5.0, metadata={"min": 0.1, "max": 100.0})
    hfov_deg: float = field(default=95.0, metadata={"min": 10.0, "max": 170.0})
    ceiling_height: float = field(default=2.5, metadata={"min": 0.2, "max": 20.0})
    offset: list[float] = field(
        default_factory=lambda: [0.0, 0.0], metadata={"min": -5.0, "max": 5.0, "len": 2}
    )
    mount_height: float = field(default=0.8, metadata={"min": 0.0, "max": 5.0})
    noise_sigma: float = field(default=3.0, metadata={"min": 0.0, "max": 100.0})
    background: float = field(default=40.0, metadata={"min": 0.0, "max": 255.0})
    # background shading: brightness falls by this much (grey levels) toward the corners
    vignetting: float = field(default=12.0, metadata={"min": 0.0, "max": 255.0})
    lamp_level: float = field(default=255.0, metadata={"min": 0.0, "max": 255.0})
    supersample: int = field(default=4, metadata={"min": 1, "max": 16})


@dataclass
class LampFailure:
    """Lamps (by index) that go dark from the start of a run."""

    run: int = field(default=5, metadata={"min": 1})
    lamps: list[int] = field(default_factory=list, metadata={"min": 0, "max": 10000})


@dataclass
class Bump:
    """The true pose turns by ``angle_deg`` in one step, unseen by odometry.

    ``fraction`` is the part of the run's lap already driven when it happens.
    """

    run: int = field(default=1, metadata={"min": 1})
    fraction: float = field(default=0.5, metadata={"min": 0.0, "max": 1.0})
    angle_deg: float = field(default=10.0, metadata={"min": -180.0, "max": 180.0})


@dataclass
class Obstacle:
    """An object the sonars see and the map does not (``sim.obstacles``; issue 8).

    ``box``: a static rectangle (centre [x, y], size [length, width], angle_deg);
    ``disc``: a person of ``radius`` walking back and forth along ``path`` at ``speed``.
    Present from the start of run ``from_run`` to the end of run ``to_run``.
    """

    kind: str = field(default="box", metadata={"choices": ["box", "disc"]})
    from_run: int = field(default=5, metadata={"min": 1})
    to_run: int = field(default=6, metadata={"min": 1})
    centre: list[float] = field(
        default_factory=lambda: [0.0, 0.0], metadata={"min": -1e4, "max": 1e4, "len": 2}
    )
    size: list[float] = field(
        default_factory=lambda: [0.5, 0.5], metadata={"min": 0.01, "max": 100.0, "len": 2}
    )
    angle_deg: float = field(default=0.0, metadata={"min": -360.0, "max": 360.0})
    radius: float = field(default=0.25, metadata={"min": 0.01, "max": 5.0})
    path: list[list[float]] = field(
        default_factory=list, metadata={"min": -1e4, "max": 1e4, "item_len": 2}
    )
    speed: float = field(default=0.5, metadata={"min": 0.0, "max": 10.0})


@dataclass
class ScenarioParams:
    """Runs (laps, alternating direction) and scheduled events.

    The robot starts on the centre line ``start_offset`` metres along it from its first
    vertex, facing along it; odd runs drive the loop forward, even runs backward, and
    between runs it turns around in place. ``lap_fraction`` < 1 shortens every run to
    part of a lap (for tests).
    """

    runs: int = field(default=6, metadata={"min": 1, "max": 1000})
    start_offset: float = field(default=5.0, metadata={"min": 0.0, "max": 1e6})
    lap_fraction: float = field(default=1.0, metadata={"min": 0.01, "max": 1.0})
    lamp_failures: list[LampFailure] = field(default_factory=list)
    bumps: list[Bump] = field(default_factory=list)
    # unexpected objects (boxes, people) seen by the sonars only
    obstacles: list[Obstacle] = field(default_factory=list)
