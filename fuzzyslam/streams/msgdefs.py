"""The ros2msg definitions (schema texts) of the messages ``run`` writes into estimates.mcap
(with fixes, the map and the fixes' markers too), as rosbags' ROS 2 Humble and Jazzy
typestores generate them, so that writing them needs no typestore (tests/test_cdr.py and
tests/test_ros_distro.py check each equals the typestore's text). Each message's own
definition is written once; a type's text is its definition followed by those of the
types it uses, each after a separator line and ``MSG: name``. Of these types Jazzy's
differ from Humble's in one line: Marker's constant ``ARROW_STRIP=12``."""

from __future__ import annotations

_SEPARATOR = "=" * 80 + "\n"

# the definition of each message type (ros2msg), once
_DEFINITIONS: dict[str, str] = {
    "std_msgs/Header": ("builtin_interfaces/Time stamp\nstring frame_id\n"),
    "builtin_interfaces/Time": ("int32 sec\nuint32 nanosec\n"),
    "geometry_msgs/PoseWithCovariance": ("geometry_msgs/Pose pose\nfloat64[36] covariance\n"),
    "geometry_msgs/Pose": ("geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n"),
    "geometry_msgs/Point": ("float64 x\nfloat64 y\nfloat64 z\n"),
    "geometry_msgs/Quaternion": ("float64 x\nfloat64 y\nfloat64 z\nfloat64 w\n"),
    "geometry_msgs/PoseWithCovarianceStamped": (
        "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n"
    ),
    "geometry_msgs/Transform": (
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n"
    ),
    "geometry_msgs/Vector3": ("float64 x\nfloat64 y\nfloat64 z\n"),
    "tf2_msgs/TFMessage": ("geometry_msgs/TransformStamped[] transforms\n"),
    "visualization_msgs/Marker": (
        "int32 ARROW=0\n"
        "int32 CUBE=1\n"
        "int32 SPHERE=2\n"
        "int32 CYLINDER=3\n"
        "int32 LINE_STRIP=4\n"
        "int32 LINE_LIST=5\n"
        "int32 CUBE_LIST=6\n"
        "int32 SPHERE_LIST=7\n"
        "int32 POINTS=8\n"
        "int32 TEXT_VIEW_FACING=9\n"
        "int32 MESH_RESOURCE=10\n"
        "int32 TRIANGLE_LIST=11\n"
        "int32 ADD=0\n"
        "int32 MODIFY=0\n"
        "int32 DELETE=2\n"
        "int32 DELETEALL=3\n"
        "std_msgs/Header header\n"
        "string ns\n"
        "int32 id\n"
        "int32 type\n"
        "int32 action\n"
        "geometry_msgs/Pose pose\n"
        "geometry_msgs/Vector3 scale\n"
        "std_msgs/ColorRGBA color\n"
        "builtin_interfaces/Duration lifetime\n"
        "bool frame_locked\n"
        "geometry_msgs/Point[] points\n"
        "std_msgs/ColorRGBA[] colors\n"
        "string texture_resource\n"
        "sensor_msgs/CompressedImage texture\n"
        "visualization_msgs/UVCoordinate[] uv_coordinates\n"
        "string text\n"
        "string mesh_resource\n"
        "visualization_msgs/MeshFile mesh_file\n"
        "bool mesh_use_embedded_materials\n"
    ),
    "std_msgs/ColorRGBA": ("float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n"),
    "builtin_interfaces/Duration": ("int32 sec\nuint32 nanosec\n"),
    "sensor_msgs/CompressedImage": ("std_msgs/Header header\nstring format\nuint8[] data\n"),
    "visualization_msgs/UVCoordinate": ("float32 u\nfloat32 v\n"),
    "visualization_msgs/MeshFile": ("string filename\nuint8[] data\n"),
    "visualization_msgs/MarkerArray": ("visualization_msgs/Marker[] markers\n"),
    "nav_msgs/OccupancyGrid": ("std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data\n"),
    "nav_msgs/MapMetaData": (
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\n"
        "uint32 height\ngeometry_msgs/Pose origin\n"
    ),
}

# the types written, with the types their text includes, in the typestore's order
_USES: dict[str, tuple[str, ...]] = {
    "geometry_msgs/msg/PoseWithCovarianceStamped": (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
    ),
    "tf2_msgs/msg/TFMessage": (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3",
        "geometry_msgs/Quaternion",
    ),
    "visualization_msgs/msg/MarkerArray": (
        "visualization_msgs/Marker",
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
        "geometry_msgs/Vector3",
        "std_msgs/ColorRGBA",
        "builtin_interfaces/Duration",
        "sensor_msgs/CompressedImage",
        "visualization_msgs/UVCoordinate",
        "visualization_msgs/MeshFile",
    ),
    "nav_msgs/msg/OccupancyGrid": (
        "std_msgs/Header",
        "builtin_interfaces/Time",
        "nav_msgs/MapMetaData",
        "geometry_msgs/Pose",
        "geometry_msgs/Point",
        "geometry_msgs/Quaternion",
    ),
}


# Jazzy's: Humble's, with Marker's constant ARROW_STRIP after TRIANGLE_LIST
_JAZZY_DEFINITIONS: dict[str, str] = {
    **_DEFINITIONS,
    "visualization_msgs/Marker": _DEFINITIONS["visualization_msgs/Marker"].replace(
        "int32 TRIANGLE_LIST=11\n", "int32 TRIANGLE_LIST=11\nint32 ARROW_STRIP=12\n"
    ),
}


def _text(name: str, definitions: dict[str, str]) -> str:
    own = definitions[name.replace("/msg/", "/")]
    return own + "".join(f"{_SEPARATOR}MSG: {d}\n{definitions[d]}" for d in _USES[name])


MSGDEFS: dict[str, str] = {name: _text(name, _DEFINITIONS) for name in _USES}
"""ROS 2 Humble's texts."""

MSGDEFS_OF: dict[str, dict[str, str]] = {
    "humble": MSGDEFS,
    "jazzy": {name: _text(name, _JAZZY_DEFINITIONS) for name in _USES},
}
"""The texts of each distribution of ``streams/distro.ROS_DISTROS``."""
