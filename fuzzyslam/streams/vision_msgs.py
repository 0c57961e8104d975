"""vision_msgs (ROS 2 Humble, vision_msgs 4.x): the detection messages that carry a
per-detection covariance, registered into the typestore (rosbags ships only the core
message packages).

A ``vision_msgs/msg/Detection3DArray`` holds one ``Detection3D`` per object seen; each
has hypotheses (``results``: class id, score, and a ``geometry_msgs/PoseWithCovariance``)
and a bounding box. fuzzyslam reads a landmark detection as the pose of the
best-scoring hypothesis (the box centre when there is none) and its x, y covariance
block as the detection's covariance (docs/contracts.md sec. 1).
"""

from __future__ import annotations

# Definitions written from the vision_msgs 4.x interface (the fields and their order are
# what the CDR bytes follow).
DEFINITIONS: dict[str, str] = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\n"
        "vision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox3D bbox\n"
        "string id\n"
    ),
    "vision_msgs/msg/Detection3DArray": (
        "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n"
    ),
}

DETECTION3D_ARRAY = "vision_msgs/msg/Detection3DArray"
