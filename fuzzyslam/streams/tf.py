"""The static tf tree of a log (/tf_static) and the planar mounts of its sensors.

A log's /tf_static holds ``parent -> child`` rigid transforms (geometry_msgs/Transform:
the child frame's origin and axes in the parent frame). A sensor's mount is the
transform from the robot's base frame (the odometry's child frame, ``base_link`` by
default; REP 105) to the sensor's frame, composed down the whole chain
(``base_footprint -> base_link -> laser_mount -> laser``), with the full 3D rotation of
every link: a laser mounted upside down (roll = pi) sees its beam at angle ``a`` point
at ``-a`` in the base frame, which a yaw-only reading would mirror. A chain that does
not reach the base is refused, except in a tree that does not name the base at all,
whose root then stands in for it (said so by the caller; :func:`compose_to_base`).

The maps and fixes are planar, so a composed mount is projected onto the base plane
(the x-y plane of the base frame; REP 103: x forward, y left, z up):

- a sensor's planar mount is ``(x, y, yaw)``: the x, y of its origin and the heading of
  its x axis (its cone axis), ``atan2(R[1, 0], R[0, 0])``;
- a laser beam at angle ``a`` in the laser frame points along ``d = (cos a, sin a, 0)``;
  its heading in the base frame is ``atan2((R d)_y, (R d)_x)``;
- a direction whose horizontal component is below :data:`MIN_HORIZONTAL` (more than
  ~78 deg from the base plane) has no meaningful heading: the sensor is refused
  (:class:`TfProblem`), never placed at an arbitrary yaw.

The rotation matrix of a quaternion (x, y, z, w) is the Hamilton-convention one used by
ROS (tf2, Eigen): J. Solà, "Quaternion kinematics for the error-state Kalman filter",
arXiv:1711.02508, 2017, sec. 2.4.1 ("the rotation matrix"); it is the transpose of the
attitude matrix of J. Diebel, "Representing attitude: Euler angles, unit quaternions,
and rotation vectors", Stanford, 2006, eq. 125. Quaternions are normalised before use;
a zero or non-finite one (an uninitialised rotation) is refused.

References: REP 103 (Standard units of measure and coordinate conventions), REP 105
(Coordinate frames for mobile platforms).
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Iterable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

# smallest horizontal component of a unit direction that still has a heading: a sensor
# axis or beam more than acos(0.2) = 78.5 deg from the base plane is refused
MIN_HORIZONTAL = 0.2

K = TypeVar("K", bound=Hashable)


class TfProblem(ValueError):
    """A static tf tree that cannot place a frame: one line saying why."""


def quaternion_matrix(q: ArrayLike) -> np.ndarray:
    """Rotation matrices of quaternions (x, y, z, w), normalised first (Hamilton; ROS).

    Parameters
    ----------
    q : array_like, shape (..., 4)
        Quaternions (qx, qy, qz, qw), not necessarily of unit norm.

    Returns
    -------
    ndarray, shape (..., 3, 3)
        ``R`` such that ``R @ v`` expresses in the parent frame a vector ``v`` of the
        child frame.

    Raises
    ------
    TfProblem
        When a quaternion is zero (within 1e-9) or not finite.
    """
    q = np.asarray(q, dtype=float)
    n = np.linalg.norm(q, axis=-1)
    bad = ~np.isfinite(n) | (n < 1e-9)
    if np.any(bad):
        raise TfProblem("a zero or non-finite rotation quaternion (an uninitialised rotation?)")
    x, y, z, w = np.moveaxis(q / n[..., None], -1, 0)
    r = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )  # fmt: skip
    return r.reshape(*q.shape[:-1], 3, 3)


def _frozen(a: ArrayLike, shape: tuple[int, ...]) -> np.ndarray:
    out = np.array(a, dtype=float).reshape(shape)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)  # arrays: no elementwise ==
class Rigid:
    """A 3D rigid transform: a child frame's origin ``translation`` (3,) and axes
    ``rotation`` (3, 3) (columns: the child's x, y, z axes) in its parent frame."""

    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "translation", _frozen(self.translation, (3,)))
        object.__setattr__(self, "rotation", _frozen(self.rotation, (3, 3)))

    @classmethod
    def planar(cls, x: float, y: float, yaw: float) -> Rigid:
        """A transform in the base plane: origin (x, y, 0), rotated by ``yaw`` about z.

        Parameters
        ----------
        x, y : float
            Origin (m).
        yaw : float
            Rotation about z (rad).

        Returns
        -------
        Rigid
        """
        c, s = np.cos(yaw), np.sin(yaw)
        return cls(np.array([x, y, 0.0]), np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]))

    def compose(self, other: Rigid) -> Rigid:
        """``self`` followed by ``other``: parent -> self's child, then -> other's child.

        Parameters
        ----------
        other : Rigid
            A transform from this transform's child frame to a further frame.

        Returns
        -------
        Rigid
            The transform from this transform's parent frame to ``other`` 's child.
        """
        return Rigid(
            self.translation + self.rotation @ other.translation, self.rotation @ other.rotation
        )

    def inverse(self) -> Rigid:
        """The transform from the child frame back to the parent frame.

        Returns
        -------
        Rigid
        """
        rt = self.rotation.T
        return Rigid(-(rt @ self.translation), rt)


@dataclass(frozen=True)
class TfTree:
    """The static tf tree: ``parents`` child -> (parent, transform of the child in the
    parent), and ``problems`` frame -> why it cannot be used (two parents, a zero
    quaternion, a non-finite translation). Frame names without a leading ``/``."""

    parents: dict[str, tuple[str, Rigid]]
    problems: dict[str, str]

    @property
    def frames(self) -> set[str]:
        """Every frame named in the tree (children and parents).

        Returns
        -------
        set of str
        """
        return set(self.parents) | set(self.problems) | {p for p, _ in self.parents.values()}


def _name(frame: Any) -> str:
    return str(frame).lstrip("/")


def static_tree(messages: Iterable[Any]) -> TfTree:
    """The static tf tree of a log's /tf_static messages (tf2_msgs/TFMessage, log order).

    A child repeated with the same parent keeps the later transform (a republished
    /tf_static); a child given two different parents, or a transform with a zero or
    non-finite rotation or a non-finite translation, is recorded as a problem of that
    frame, raised only when a chain passes through it.

    Parameters
    ----------
    messages : iterable of TFMessage
        The messages (rosbags or ``streams/cdr_messages.py`` classes).

    Returns
    -------
    TfTree
    """
    parents: dict[str, tuple[str, Rigid]] = {}
    problems: dict[str, str] = {}
    for msg in messages:
        stamped = list(msg.transforms)
        if not stamped:
            continue
        tr = np.array([[t.transform.translation.x, t.transform.translation.y,
                        t.transform.translation.z] for t in stamped], dtype=float)  # fmt: skip
        q = np.array([[t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z,
                       t.transform.rotation.w] for t in stamped], dtype=float)  # fmt: skip
        n = np.linalg.norm(q, axis=-1)
        q_ok = np.isfinite(n) & (n >= 1e-9)
        rot = np.broadcast_to(np.eye(3), (len(stamped), 3, 3)).copy()
        if q_ok.any():
            rot[q_ok] = quaternion_matrix(q[q_ok])
        for k, ts in enumerate(stamped):
            child, parent = _name(ts.child_frame_id), _name(ts.header.frame_id)
            old = parents.get(child)
            if old is not None and old[0] != parent:
                problems[child] = f"frame {child!r} has two parents, {old[0]!r} and {parent!r}"
                continue
            if child in problems and problems[child].startswith(f"frame {child!r} has two"):
                continue  # a conflict stays a conflict
            if not q_ok[k]:
                problems[child] = (
                    f"frame {child!r} has a zero or non-finite rotation quaternion "
                    f"(an uninitialised rotation?) under {parent!r}"
                )
                continue
            if not np.all(np.isfinite(tr[k])):
                problems[child] = f"frame {child!r} has a non-finite translation under {parent!r}"
                continue
            problems.pop(child, None)  # a later valid transform replaces a bad one
            parents[child] = (parent, Rigid(tr[k], rot[k]))
    return TfTree(parents, problems)


# a transform of a dynamic tf stream that moves less than this over the log is a mount
CONSTANT_M = 1e-3
CONSTANT_RAD = 1e-3


def constant_transforms(messages: Iterable[Any]) -> list[Any]:
    """The transforms of a dynamic tf stream (/tf) that never change: a ROS 1 robot's
    mounts, broadcast by tf's ``static_transform_publisher`` at a fixed rate before tf2
    gave them /tf_static (and converted so by ``rosbags-convert``).

    A (parent, child) pair is constant when every one of its samples lies within
    ``CONSTANT_M`` (translation) and ``CONSTANT_RAD`` (the rotation between the two
    quaternions, 2 acos |q . q0|) of its first; a child seen under two parents, a zero or
    non-finite quaternion or a non-finite translation is left out (:func:`static_tree`
    says why where a chain needs it). The odometry's odom -> base moves, and is left out
    too, unless the robot never moved.

    Parameters
    ----------
    messages : iterable of TFMessage
        The /tf messages, in log order.

    Returns
    -------
    list of TransformStamped
        The first sample of each constant pair, in order of first sight.
    """
    first: dict[str, Any] = {}
    ref: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}  # parent, translation, unit q
    out_of: set[str] = set()  # moved, two parents or bad: no mount (no samples kept)
    cos_half = math.cos(CONSTANT_RAD / 2.0)
    for msg in messages:
        for ts in msg.transforms:
            child, par = _name(ts.child_frame_id), _name(ts.header.frame_id)
            if child in out_of:
                continue
            t, q = ts.transform.translation, ts.transform.rotation
            tr = np.array([t.x, t.y, t.z], dtype=float)
            qv = np.array([q.x, q.y, q.z, q.w], dtype=float)
            n = float(np.linalg.norm(qv))
            if not (np.all(np.isfinite(tr)) and math.isfinite(n) and n >= 1e-9):
                out_of.add(child)
                continue
            qv /= n
            if child not in ref:
                first[child], ref[child] = ts, (par, tr, qv)
                continue
            p0, tr0, q0 = ref[child]
            # |q . q0|: q and -q are one rotation; the angle between them is 2 acos of it
            if p0 != par or np.abs(tr - tr0).max() > CONSTANT_M or abs(qv @ q0) < cos_half:
                out_of.add(child)
    return [ts for child, ts in first.items() if child not in out_of]


def _up(tree: TfTree, frame: str, base: str | None) -> tuple[Rigid, str]:
    """(transform of ``frame`` in the last frame reached, that frame): up the parent
    chain until ``base`` (None: never) or the root. TfProblem on a problem frame or a
    cycle."""
    out = Rigid()
    chain = [frame]
    f = frame
    while f != base:
        if f in tree.problems:
            raise TfProblem(tree.problems[f])
        link = tree.parents.get(f)
        if link is None:
            break
        parent, t = link
        out = t.compose(out)
        if parent in chain:
            loop = [*chain[chain.index(parent) :], parent][::-1]  # parent -> child order
            raise TfProblem(f"the frames form a cycle ({' -> '.join(loop)})")
        chain.append(parent)
        f = parent
    return out, f


# names of world-fixed frames (REP 105): never the robot's base, even as a chain's root
WORLD_FRAMES = frozenset({"odom", "map", "world", "earth"})


def _is_world(frame: str) -> bool:
    return frame.rsplit("/", 1)[-1] in WORLD_FRAMES  # also a namespaced "robot1/odom"


def locate(tree: TfTree, frame: str, base: str = "base_link") -> tuple[Rigid, str | None] | None:
    """The mount of ``frame`` in ``base`` (:func:`compose_to_base`), and the root taken as
    the base when the tree does not name ``base`` at all.

    Parameters
    ----------
    tree : TfTree
        The static tree (:func:`static_tree`).
    frame : str
        The sensor's frame (a leading ``/`` ignored).
    base : str
        The robot's base frame (the odometry's child frame).

    Returns
    -------
    tuple of (Rigid, str or None) or None
        The composed transform, and None when it is expressed in ``base`` itself, else
        the name of the chain's root that stands in for ``base``; None when the tree
        does not name ``frame``.

    Raises
    ------
    TfProblem
        As :func:`compose_to_base`.
    """
    frame, base = _name(frame), _name(base)
    if frame == base:
        return Rigid(), None
    if frame not in tree.frames:
        return None
    out, top = _up(tree, frame, base)
    if top == base:
        return out, None
    if base in tree.parents or base in tree.problems:
        base_in_root, base_top = _up(tree, base, None)
        if base_top == top:
            return base_in_root.inverse().compose(out), None
    if base in tree.frames or _is_world(top):
        raise TfProblem(
            f"frame {frame!r} is not connected to the base frame {base!r} in /tf_static "
            f"(its chain ends at {top!r})"
        )
    return out, top


def compose_to_base(tree: TfTree, frame: str, base: str = "base_link") -> Rigid | None:
    """The mount of ``frame``: its transform in ``base``, composed up the parent chain.

    The chain is followed from ``frame`` up to ``base``. When it does not pass through
    ``base`` it ends at its root (the topmost frame, with no parent):

    - ``base`` hangs under the same root (a sibling branch: ``base_footprint ->
      base_link`` and ``base_footprint -> laser``): the mount is expressed in ``base``
      through the root;
    - ``base`` is elsewhere in the tree (under another root, or a root itself), or the
      root is a world-fixed frame (``odom``, ``map``, ``world``, ``earth``; REP 105):
      the sensor is not connected to the robot, :class:`TfProblem`;
    - the tree does not name ``base`` at all (the odometry's child frame is named
      differently from the tree's root): the mount is expressed in the root, which
      stands in for ``base`` (:func:`locate` names it, for the caller to report).

    Parameters
    ----------
    tree : TfTree
        The static tree (:func:`static_tree`).
    frame : str
        The sensor's frame (a message's ``header.frame_id``; a leading ``/`` ignored).
    base : str
        The robot's base frame (the odometry's child frame).

    Returns
    -------
    Rigid or None
        The composed transform (identity when ``frame`` is ``base``); None when the tree
        does not name ``frame`` (no mount).

    Raises
    ------
    TfProblem
        When the chain passes through a frame with two parents or a bad transform, runs
        in a cycle, or does not reach the base (above).
    """
    found = locate(tree, frame, base)
    return None if found is None else found[0]


def frame_mounts(
    messages: Iterable[Any],
    frames: dict[K, str],
    base: str = "base_link",
    stand_ins: dict[K, str] | None = None,
) -> tuple[dict[K, Rigid], list[K], dict[K, str]]:
    """The composed mounts of several sensors from one /tf_static.

    Parameters
    ----------
    messages : iterable of TFMessage
        The /tf_static messages, in log order.
    frames : dict
        Key (a topic) -> the sensor's frame.
    base : str
        The robot's base frame (:func:`compose_to_base`).
    stand_ins : dict, optional
        Filled with key -> the root that stands in for ``base`` (a tree that does not
        name ``base``; :func:`locate`), for the keys placed so.

    Returns
    -------
    mounts : dict
        Key -> its :class:`Rigid` mount in ``base``, for the keys that have one.
    missing : list
        The keys whose frame the tree does not name, in ``frames`` order.
    problems : dict
        Key -> why its frame cannot be placed (one line).
    """
    tree = static_tree(messages)
    mounts: dict[K, Rigid] = {}
    missing: list[K] = []
    problems: dict[K, str] = {}
    for key, frame in frames.items():
        try:
            found = locate(tree, frame, base)
        except TfProblem as e:
            problems[key] = str(e)
            continue
        if found is None:
            missing.append(key)
            continue
        mounts[key] = found[0]
        if found[1] is not None and stand_ins is not None:
            stand_ins[key] = found[1]
    return mounts, missing, problems


def planar_headings(rotation: ArrayLike, directions: ArrayLike) -> np.ndarray:
    """Headings in the base plane of directions of a rotated frame.

    Parameters
    ----------
    rotation : array_like, shape (3, 3)
        The frame's axes in the base frame (:attr:`Rigid.rotation`).
    directions : array_like, shape (M, 3)
        Unit directions in the frame.

    Returns
    -------
    ndarray, shape (M,)
        ``atan2((R d)_y, (R d)_x)`` of each direction ``d`` (rad, in (-pi, pi]).

    Raises
    ------
    TfProblem
        When a direction's horizontal component is below :data:`MIN_HORIZONTAL` (too
        close to vertical for a heading).
    """
    v = np.asarray(directions, dtype=float).reshape(-1, 3) @ np.asarray(rotation, float).T
    h = np.hypot(v[:, 0], v[:, 1])
    if np.any(h < MIN_HORIZONTAL):
        worst = float(np.degrees(np.arctan2(np.abs(v[:, 2]), h)).max())
        limit = float(np.degrees(np.arccos(MIN_HORIZONTAL)))
        raise TfProblem(
            f"tilted {worst:.0f} deg out of the base plane (more than {limit:.0f} deg): "
            "no planar heading"
        )
    return np.arctan2(v[:, 1], v[:, 0])


def planar_mount(mount: Rigid) -> np.ndarray:
    """The planar mount of a sensor: its origin's x, y and its x axis' heading.

    Parameters
    ----------
    mount : Rigid
        The sensor's composed mount in the base frame.

    Returns
    -------
    ndarray, shape (3,)
        (x, y, yaw): ``yaw = atan2(R[1, 0], R[0, 0])``.

    Raises
    ------
    TfProblem
        When the x axis is too close to vertical (:func:`planar_headings`).
    """
    yaw = planar_headings(mount.rotation, [[1.0, 0.0, 0.0]])[0]
    return np.array([mount.translation[0], mount.translation[1], yaw])


def beam_mounts(mount: Rigid, angles: ArrayLike) -> np.ndarray:
    """Planar poses of a laser's beams: each beam at the laser's origin, headed along
    its direction ``(cos a, sin a, 0)`` in the laser frame rotated into the base frame.

    Parameters
    ----------
    mount : Rigid
        The laser's composed mount in the base frame.
    angles : array_like, shape (M,)
        Beam angles in the laser frame (rad; REP 103: counter-clockwise from x).

    Returns
    -------
    ndarray, shape (M, 3)
        (x, y, yaw) of each beam; with a laser upside down (roll = pi) ``yaw = mount
        yaw - a``.

    Raises
    ------
    TfProblem
        When a beam is too close to vertical (:func:`planar_headings`).
    """
    a = np.asarray(angles, dtype=float).reshape(-1)
    d = np.column_stack([np.cos(a), np.sin(a), np.zeros_like(a)])
    yaw = planar_headings(mount.rotation, d)
    xy = np.broadcast_to(mount.translation[:2], (len(a), 2))
    return np.column_stack([xy, yaw])
