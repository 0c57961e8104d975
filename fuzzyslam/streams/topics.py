"""Topic names of a log (the one place for them). Configurable for real robot logs."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class Topics:
    """Topic names read and written by every stage (config section ``topics``)."""

    joint_states: str = "/joint_states"
    odom: str = "/odom"
    sonar_prefix: str = "/sonar/s"
    scan: str = "/scan"
    tf_static: str = "/tf_static"
    tf: str = "/tf"
    image: str = "/ceiling_camera/image_raw"
    camera_info: str = "/ceiling_camera/camera_info"
    detections: str = "/ceiling_camera/detections"
    ground_truth: str = "/ground_truth/odom"
    events: str = "/sim/events"
    world_markers: str = "/sim/world"
    slam_pose: str = "/slam/pose"
    slam_landmarks: str = "/slam/landmarks"
    slam_changes: str = "/slam/changes"
    map: str = "/map"
    map_conflict: str = "/map_conflict"
    map_references: str = "/map_references"
    heading_fixes: str = "/slam/heading_fixes"
    pose_fixes: str = "/slam/pose_fixes"

    def latched(self) -> frozenset[str]:
        """The topics published once and kept for late subscribers (transient local
        QoS, as ``/tf_static`` and nav2's ``/map`` are): the static transforms, the map
        layers and the simulated world."""
        return frozenset(
            (self.tf_static, self.map, self.map_conflict, self.map_references, self.world_markers)
        )

    def sonar(self, i: int) -> str:
        """Topic of sonar ``i`` (``/sonar/s00`` .. ``/sonar/s15``)."""
        return f"{self.sonar_prefix}{i:02d}"
