"""The ROS 2 distribution whose message definitions the MCAP outputs carry (the config's
``output.ros_distro``).

``ros2 bag play`` publishes a log's CDR bytes as they are, to subscribers compiled with
the message definitions of the distribution it runs on, so a file must be written with
the definitions of the distribution it is played on. Of the messages fuzzyslam writes,
Humble and Jazzy (the LTS releases; rosbags' typestores of each) differ in two:

- ``sensor_msgs/msg/Range`` ends with ``float32 variance`` from Iron on (the CDR bytes
  are 4 longer);
- ``visualization_msgs/msg/Marker`` has the constant ``ARROW_STRIP=12`` in Jazzy (its
  schema text only: the fields, texture and mesh ones included, and so the bytes, are
  Humble's).

Every other type written (Odometry, JointState, Image, CameraInfo, TFMessage,
PoseWithCovarianceStamped, MarkerArray, OccupancyGrid, String and the types they hold) is
the same in both. Humble is the default: every output stays byte for byte what it was
before the choice (data/sample.mcap included), and Foxglove and rosbags read either.
"""

from __future__ import annotations

from dataclasses import dataclass, field

ROS_DISTROS: tuple[str, ...] = ("humble", "jazzy")
DEFAULT_ROS_DISTRO = "humble"


@dataclass
class OutputParams:
    """The MCAP outputs' format (``simulate``'s log, ``run``'s estimates.mcap, ``map``'s
    fgm.mcap): ``ros_distro``, the ROS 2 distribution whose message definitions, CDR
    layouts and rosbag2 ``ROS_DISTRO`` record they carry."""

    ros_distro: str = field(default=DEFAULT_ROS_DISTRO, metadata={"choices": ROS_DISTROS})


def check_distro(name: str) -> str:
    """``name`` if it is one of :data:`ROS_DISTROS`, else a ValueError naming them.

    Parameters
    ----------
    name : str
        A distribution's name, e.g. ``"jazzy"``.

    Returns
    -------
    str
        ``name``.
    """
    if name not in ROS_DISTROS:
        raise ValueError(f"ROS 2 distribution {name!r}: not one of {', '.join(ROS_DISTROS)}")
    return name
