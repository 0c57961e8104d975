"""The static transforms a log places its sensors with: /tf_static, and, where it does
not place a sensor's frame, the transforms of /tf that never change.

A ROS 2 log (and a ROS 1 one recorded with tf2's static publishers) holds its mounts on
/tf_static. A ROS 1 log whose mounts were broadcast by tf's ``static_transform_publisher``
holds them on /tf instead, republished at a fixed rate among the odometry's moving
transforms; a conversion by ``rosbags-convert`` keeps them there. Those are read
(:func:`fuzzyslam.streams.tf.constant_transforms`) only when /tf_static leaves a
sensor's frame unplaced, so a log with a complete /tf_static costs no /tf read.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.tf import TfProblem, TfTree, constant_transforms, locate, static_tree
from fuzzyslam.streams.topics import Topics


def _unplaced(tree: TfTree, frames: Iterable[str], base: str) -> bool:
    """Whether a frame of ``frames`` is not placed on ``base`` by ``tree``."""
    for frame in frames:
        try:
            if locate(tree, frame, base) is None:
                return True
        except TfProblem:  # e.g. a chain that ends elsewhere: /tf may join it to the base
            return True
    return False


def static_messages(
    reader: LogReader, topics: Topics, frames: Iterable[str], base: str
) -> tuple[list[Any], str]:
    """The log's static transforms for placing sensors in ``frames`` on ``base``.

    Parameters
    ----------
    reader : LogReader
        The log.
    topics : Topics
        Its ``tf_static`` and ``tf`` topics.
    frames : iterable of str
        The sensors' frames (``header.frame_id`` of their messages).
    base : str
        The robot's base frame.

    Returns
    -------
    messages : list of TFMessage
        /tf_static's messages, then, when they leave a frame unplaced and /tf has
        constant transforms of children they lack, one message of those.
    source : str
        Where the transforms came from, for the summaries' ``mounts_source``:
        ``topics.tf_static``, or ``"/tf (constant transforms)"`` or
        ``"/tf_static and /tf (constant transforms)"``.
    """
    frames = list(frames)
    msgs = (
        [m.msg for m in reader.messages([topics.tf_static])] if reader.has(topics.tf_static) else []
    )
    tree = static_tree(msgs)
    if not reader.has(topics.tf) or not _unplaced(tree, frames, base):
        return msgs, topics.tf_static
    known = set(tree.parents)
    extra = [
        ts
        for ts in constant_transforms(m.msg for m in reader.messages([topics.tf]))
        if str(ts.child_frame_id).lstrip("/") not in known
    ]
    if not extra:
        return msgs, topics.tf_static
    what = f"{topics.tf} (constant transforms)"
    return [*msgs, M.tf_message(extra)], (f"{topics.tf_static} and {what}" if msgs else what)
