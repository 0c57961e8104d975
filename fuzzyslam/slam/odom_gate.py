"""Odometry glitches: increments a wheeled robot cannot make (the one home of odometry
plausibility).

Two tests, both used by log-to-events (slam/inputs.py):

- :func:`within_speed`, on every odometry increment (wheel encoders or poses): the
  physical bound, ``SPEED_MARGIN`` times the robot's top speed and turn rate over the
  increment's time plus ``SLACK_S`` (a wheel angle of +1e6 rad is a glitch, not motion);
  after ``REANCHOR`` refusals in a row the reading is the new reference;
- :class:`OdomGate`, on nav_msgs/Odometry poses: the arc gate below.

A nav_msgs/Odometry stream from a real log may carry stray poses (a converter's
placeholder, a reset, a pose of another stream): a jump of a metre sideways and back.
Integrated as motion, the jump does not cancel with the jump back (each increment is
integrated along its own mid heading) and leaves a permanent offset. An increment from
the last accepted pose is refused when it is impossible for a differential-drive robot:

- faster than ``max_speed`` m/s or ``max_turn_rate`` rad/s; or
- not an arc: a differential-drive robot moves along a circular arc between two
  samples, so its chord points at half the heading change from the start heading
  (Thrun, Burgard and Fox, *Probabilistic Robotics*, sec. 5.4: the odometry model's
  rot1 = d_rot / 2 for an arc). A chord whose lateral offset from that direction
  (forwards or backwards) exceeds ``lateral_tol + lateral_frac * chord`` is a jump.

A stray pose is an excursion that comes back: the refused poses are skipped and the next
increment is measured from the last accepted pose. After ``reset_after`` refusals in a
row the stream has not come back: it really moved (a correction of the pose stream, a
turn faster than the limits), and the latest pose is accepted with the whole increment
from the last accepted one (``"reset"``: the motion is kept, only delayed).

A driver restart (``restarts``) is told from both as soon as it is unambiguous: the pose
jumps to near the odometry's origin (0, 0, 0), where a robot that restarted its
odometry is, and then goes on smoothly from there. A refused pose that the robot can
have reached from the origin since the last accepted pose (the arc test above, from
(0, 0, 0) over that time) is a candidate; ``RESTART_CONFIRM`` or more poses after it,
each a plausible increment from the one before and none a plausible one from the last
accepted pose (the stream did not come back), the last of them moved away from the
candidate by more than ``RESTART_MOVED_M`` or turned by more than
``RESTART_MOVED_RAD``, confirm it (``"restart"``: the candidate and the poses after it,
:attr:`OdomGate.restarted`, are the new stream, read from the origin on). A pose at the
origin always passes the test from the origin, and identical poses always go on
"smoothly" from each other: without the motion a burst of placeholder zeros (a converter
or a driver that publishes (0, 0, 0) while it has no pose) would confirm a restart and
throw the stream's position away. So a single stray pose at the origin, one that the
stream then leaves, and a burst of poses that do not move are refused as any other; a
driver that restarts while the robot stands still ends in the ``"reset"`` above after
``reset_after`` refusals (the robot stood: no motion to lose).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

SPEED_MARGIN = 3.0  # increments over this many times the robot's top speed: refused
SLACK_S = 0.2  # s of top speed always allowed (stamp jitter, a first message)
REANCHOR = 5  # after this many refusals in a row, restart from the latest reading
RESTART_CONFIRM = 2  # poses that go on from a pose at the origin: a driver restart
# ... and move away from it by more than this: a standing robot's odometry does not.
# Wheel odometry at rest changes by at most a tick of encoder jitter (a coarse 500
# ticks per turn on a 0.08 m wheel: 1 mm, 0.2 deg of heading on a 0.3 m base) and a
# gyro-fused heading drifts by its bias (0.1 deg/s: 0.05 deg in the half second the
# gate can wait, ``reset_after`` poses at 20 Hz); 1 cm and 1 deg are five to ten ticks,
# and what a robot moving at 2 cm/s or turning at 2 deg/s covers in that half second.
RESTART_MOVED_M = 0.01
RESTART_MOVED_RAD = math.radians(1.0)
ORIGIN = (0.0, 0.0, 0.0)  # where a restarted driver's odometry starts (its odom frame's)


def within_speed(
    dt: float, d_trans: float, d_rot: float, max_speed: float, max_turn_rate: float
) -> bool:
    """An increment (d_trans m, d_rot rad) the robot can drive in ``dt`` s: |d_trans| and
    |d_rot| within ``SPEED_MARGIN`` times ``max_speed`` and ``max_turn_rate`` over
    ``dt + SLACK_S``.

    Parameters
    ----------
    dt : float
        The time between the poses (s).
    d_trans : float
        Translation (m).
    d_rot : float
        Rotation (rad).
    max_speed : float
        m/s.
    max_turn_rate : float
        rad/s.

    Returns
    -------
    bool
    """
    span = SPEED_MARGIN * (max(dt, 0.0) + SLACK_S)
    return abs(d_trans) <= max_speed * span and abs(d_rot) <= max_turn_rate * span


@dataclass
class OdomGate:
    """Refuses impossible odometry increments (module docstring); state: the last
    accepted pose and time, the refusals in a row."""

    max_speed: float = 2.0
    max_turn_rate: float = 2.0 * math.pi
    lateral_tol: float = 0.15
    lateral_frac: float = 0.2
    reset_after: int = 10
    restarts: bool = False  # tell a driver restart to the origin (module docstring)
    _pose: np.ndarray | None = None
    _t: float = 0.0
    _refused: int = 0
    # a restart's candidate and the poses that went on from it: (t, pose) each
    _pending: list = field(default_factory=list)
    # after "restart": the new stream's poses so far, the candidate first ((t, pose) each)
    restarted: list = field(default_factory=list)

    def prime(self, t: float, pose: np.ndarray) -> None:
        """Start from a known reference pose (e.g. :func:`first_plausible_pose`).

        Parameters
        ----------
        t : float
            Its time (s).
        pose : ndarray, shape (3,)
            The reference pose.
        """
        self._pose, self._t, self._refused = np.asarray(pose, dtype=float), float(t), 0
        self._pending = []

    @property
    def pose(self) -> np.ndarray | None:
        """The last accepted pose (the reference of the next increment)."""
        return self._pose

    def step(self, t: float, pose: np.ndarray) -> str:
        """``"first"``, ``"ok"`` (an increment from :attr:`pose` to ``pose``),
        ``"jump"`` (refused), ``"reset"`` (accepted after refusals: an increment from the
        previous reference, read before the call, to ``pose``) or ``"restart"`` (the
        driver restarted at the origin: :attr:`restarted` holds the poses since, the
        last one ``pose``; module docstring).

        Parameters
        ----------
        t : float
            The pose's time (s).
        pose : ndarray, shape (3,)
            The stream's next pose.

        Returns
        -------
        str
            first, ok, jump, reset or restart.
        """
        if self._pose is None:
            self._pose, self._t = pose, t
            return "first"
        if self.plausible(self._pose, pose, t - self._t):
            self._pose, self._t, self._refused = pose, t, 0
            if self._pending:
                self._pending = []
            return "ok"
        if self.restarts and self._restart(t, pose):
            self._pose, self._t, self._refused = pose, t, 0
            self.restarted, self._pending = self._pending, []
            return "restart"
        self._refused += 1
        if self._refused >= self.reset_after:
            self._pose, self._t, self._refused, self._pending = pose, t, 0, []
            return "reset"
        return "jump"

    def _restart(self, t: float, pose) -> bool:
        """Follow a refused pose as a possible restart (module docstring): True when it
        confirms one."""
        pend = self._pending
        if pend:
            t_last, last = pend[-1]
            if self.plausible(last, pose, t - t_last):
                pend.append((t, pose))
                return len(pend) > RESTART_CONFIRM and moved(pend[0][1], pose)
        # since the last accepted pose, could the robot have come here from the origin?
        self._pending = [(t, pose)] if self.plausible(ORIGIN, pose, t - self._t) else []
        return False

    def plausible(self, a: np.ndarray, b: np.ndarray, dt: float) -> bool:
        """Whether the increment from pose ``a`` to ``b`` in ``dt`` s is possible.

        Parameters
        ----------
        a, b : ndarray, shape (3,)
            The poses.
        dt : float
            The time between them (s).

        Returns
        -------
        bool
        """
        # rel = between(a, b) on floats (called for every odometry message)
        dx, dy = float(b[0]) - float(a[0]), float(b[1]) - float(a[1])
        c, s = math.cos(float(a[2])), math.sin(float(a[2]))
        rel = (c * dx + s * dy, -s * dx + c * dy)
        chord = math.hypot(rel[0], rel[1])
        d_rot = math.remainder(float(b[2]) - float(a[2]), math.tau)
        dt = max(dt, 1e-3)
        if chord > self.max_speed * dt or abs(d_rot) > self.max_turn_rate * dt:
            return False
        # lateral offset of the chord from the arc's direction d_rot / 2 (either sense)
        lateral = abs(-rel[0] * math.sin(0.5 * d_rot) + rel[1] * math.cos(0.5 * d_rot))
        return lateral <= self.lateral_tol + self.lateral_frac * chord


def moved(a, b) -> bool:
    """Whether pose ``b`` is more than ``RESTART_MOVED_M`` from pose ``a`` or turned by
    more than ``RESTART_MOVED_RAD`` from it: motion a standing robot's odometry does not
    show (its noise is below both).

    Parameters
    ----------
    a, b : array_like, shape (3,)
        The poses (x, y, theta).

    Returns
    -------
    bool
    """
    d = math.hypot(float(b[0]) - float(a[0]), float(b[1]) - float(a[1]))
    turn = abs(math.remainder(float(b[2]) - float(a[2]), math.tau))
    return d > RESTART_MOVED_M or turn > RESTART_MOVED_RAD


def first_plausible_pose(
    t: np.ndarray, poses: np.ndarray, gate: OdomGate | None = None, look: int = 5, need: int = 3
) -> tuple[float, np.ndarray] | None:
    """(time, pose) of the stream's first confirmed pose: the first of ``poses`` (N, 3) at
    times (N,) from which at least ``need`` of the next ``look`` poses are plausible
    increments (``gate``'s test; a stray first pose is not confirmed by the stream that
    follows it). The first pose when none is; None for no pose.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times (s).
    poses : ndarray, shape (N, 3)
        The stream's poses.
    gate : OdomGate, optional
        The test (default limits).
    look : int
        Poses looked at after a candidate.
    need : int
        Of them, how many must be plausible.

    Returns
    -------
    (float, ndarray of shape (3,)) or None
    """
    gate = gate if gate is not None else OdomGate()
    t = np.asarray(t, dtype=float)
    poses = np.asarray(poses, dtype=float).reshape(-1, 3)
    for i in range(len(t)):
        nxt = range(i + 1, min(i + 1 + look, len(t)))
        ok = sum(gate.plausible(poses[i], poses[j], t[j] - t[i]) for j in nxt)
        if ok >= min(need, len(nxt)) and len(nxt):
            return float(t[i]), poses[i]
    return (float(t[0]), poses[0]) if len(t) else None


def plausible_mask(t: np.ndarray, poses: np.ndarray, gate: OdomGate | None = None) -> np.ndarray:
    """(N,) bool: the poses the gate keeps (accepted or reset), starting from the first
    confirmed pose (:func:`first_plausible_pose`); the others refused.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times (s).
    poses : ndarray, shape (N, 3)
        The stream's poses.
    gate : OdomGate, optional
        The test (default limits).

    Returns
    -------
    ndarray of bool, shape (N,)
    """
    return gate_steps(t, poses, gate) != "jump"


def gate_steps(t: np.ndarray, poses: np.ndarray, gate: OdomGate | None = None) -> np.ndarray:
    """(N,) str: what the gate makes of each pose (:meth:`OdomGate.step`: ``ok``, ``jump``
    refused, ``reset`` taken after ``reset_after`` refusals in a row, ...), starting from
    the first confirmed pose (:func:`first_plausible_pose`).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Times (s).
    poses : ndarray, shape (N, 3)
        The stream's poses.
    gate : OdomGate, optional
        The test (default limits).

    Returns
    -------
    ndarray of str, shape (N,)
    """
    gate = gate if gate is not None else OdomGate()
    first = first_plausible_pose(t, poses, gate)
    if first is not None:
        gate.prime(*first)
    return np.array([gate.step(float(ti), p) for ti, p in zip(t, poses, strict=True)])
