"""The ROS 2 message typestores (rosbags) used for every message read or written but the
fast paths of streams/cdr.py and streams/cdr_encode.py; rosbags is imported on first use
(0.12 s of start-up with the typestore: a lamps-only ``run`` does without it).

Messages are read with Humble's (a log's own definitions first: :func:`file_deserializer`);
they are written with the definitions of the output's distribution (``distro``, one of
``streams/distro.ROS_DISTROS``; Humble by default).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache, lru_cache
from typing import TYPE_CHECKING, Any

from fuzzyslam.streams.distro import DEFAULT_ROS_DISTRO, ROS_DISTROS, check_distro
from fuzzyslam.streams.msgdefs import MSGDEFS_OF
from fuzzyslam.streams.vision_msgs import DEFINITIONS

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore


def typestore(distro: str = DEFAULT_ROS_DISTRO) -> Typestore:
    """The typestore of a ROS 2 distribution (standard message types) with the vision_msgs
    detection types (streams/vision_msgs.py, the same in Humble and Jazzy) registered;
    one per distribution, made on first use.

    Parameters
    ----------
    distro : str
        One of ``streams/distro.ROS_DISTROS`` (default Humble).

    Returns
    -------
    rosbags.typesys.store.Typestore
    """
    return _typestore(distro)


@lru_cache(maxsize=len(ROS_DISTROS))
def _typestore(distro: str) -> Typestore:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores[f"ROS2_{check_distro(distro).upper()}"])
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


def msgtype(name: str, distro: str = DEFAULT_ROS_DISTRO) -> Any:
    """The message class of a type name, e.g. msgtype('sensor_msgs/msg/Range'), in the
    typestore of ``distro`` (default Humble)."""
    return typestore(distro).types[normalise_typename(name)]


def field_names(name: str, distro: str = DEFAULT_ROS_DISTRO) -> tuple[str, ...]:
    """The fields of a message type in ``distro``, in order.

    Parameters
    ----------
    name : str
        The type name, e.g. 'sensor_msgs/msg/Range'.
    distro : str
        One of ``streams/distro.ROS_DISTROS``.

    Returns
    -------
    tuple of str
        E.g. Range's in Jazzy end with 'range', 'variance'.
    """
    return tuple(f[0] for f in typestore(distro).fielddefs[normalise_typename(name)][1])


@cache
def msgdef(name: str, distro: str = DEFAULT_ROS_DISTRO) -> str:
    """The ros2msg definition text of a type, with dependencies as 'MSG: pkg/Type' blocks,
    in ``distro`` (default Humble): the typestore's; of the types in streams/msgdefs.py,
    its copy of that text."""
    name = normalise_typename(name)
    known = MSGDEFS_OF[check_distro(distro)]
    if name in known:
        return known[name]
    text, _ = typestore(distro).generate_msgdef(name, ros_version=2)
    return text


def serialize(msg: Any, name: str, distro: str = DEFAULT_ROS_DISTRO) -> bytes:
    """CDR bytes of a message by the definition of ``distro`` (default Humble; a message
    of another distribution's class is written by its fields of that name)."""
    return bytes(typestore(distro).serialize_cdr(msg, normalise_typename(name)))


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
