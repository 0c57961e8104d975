"""The ROS 2 message typestore (rosbags) used for every message read or written but the
fast paths of streams/cdr.py and streams/cdr_encode.py; rosbags is imported on first use
(0.12 s of start-up with the typestore: a lamps-only ``run`` does without it)."""

from __future__ import annotations

from collections.abc import Callable
from functools import cache, lru_cache
from typing import TYPE_CHECKING, Any

from fuzzyslam.streams.msgdefs import MSGDEFS
from fuzzyslam.streams.vision_msgs import DEFINITIONS

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    """The ROS 2 Humble typestore (standard message types) with the vision_msgs detection
    types (streams/vision_msgs.py) registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def normalise_typename(name: str) -> str:
    """'sensor_msgs/Range' or 'sensor_msgs/msg/Range' -> 'sensor_msgs/msg/Range'."""
    parts = name.split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name


def msgtype(name: str) -> Any:
    """The message class of a type name, e.g. msgtype('sensor_msgs/msg/Range')."""
    return typestore().types[normalise_typename(name)]


@cache
def msgdef(name: str) -> str:
    """The ros2msg definition text of a type, with dependencies as 'MSG: pkg/Type' blocks
    (the typestore's; of the types in streams/msgdefs.py, its copy of that text)."""
    name = normalise_typename(name)
    if name in MSGDEFS:
        return MSGDEFS[name]
    text, _ = typestore().generate_msgdef(name, ros_version=2)
    return text


def serialize(msg: Any, name: str) -> bytes:
    """CDR bytes of a message."""
    return bytes(typestore().serialize_cdr(msg, normalise_typename(name)))


def deserialize(data: bytes | memoryview, name: str) -> Any:
    """Message object from CDR bytes."""
    return typestore().deserialize_cdr(data, normalise_typename(name))


def file_deserializer(name: str, text: str) -> Callable[[Any], Any]:
    """A deserializer of type ``name`` by a log's own message definition (its Schema
    record's ros2msg text, dependencies as ``MSG: pkg/Type`` blocks), as rosbags'
    AnyReader reads a log: a message whose definition changed between ROS 2 releases
    (vision_msgs' detections between Foxy and Humble) is read as the log recorded it.
    Made on its first call (rosbags is imported only for a message that needs it); a
    text that does not parse falls back to the typestore's definition.

    Parameters
    ----------
    name : str
        The (normalised) type name.
    text : str
        The definition text.

    Returns
    -------
    callable
        CDR bytes -> message.
    """
    made: list[Callable[[Any], Any]] = []

    def deserialize_by_definition(buf):
        if not made:
            made.append(_definition_deserializer(name, text) or (lambda b: deserialize(b, name)))
        return made[0](buf)

    return deserialize_by_definition


def _definition_deserializer(name: str, text: str) -> Callable[[Any], Any] | None:
    """rosbags' deserializer of ``name`` from ``text`` alone (None: it does not parse or
    does not define ``name``)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    try:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(text, name))
    except Exception:  # a definition rosbags cannot read: the typestore's instead
        return None
    if name not in store.types:
        return None
    return lambda buf: store.deserialize_cdr(buf, name)
