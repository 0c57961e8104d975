"""The oracle driver: a pure-pursuit path follower on the TRUE pose (pure).

A run drives the centre line once around the loop (or ``lap_fraction`` of it) from
the start point, odd runs forward and even runs backward; between runs the robot
turns around in place. The follower steers toward a look-ahead point on the path
(pure pursuit, Coulter 1992, "Implementation of the pure pursuit path tracking
algorithm", CMU-RI-TR-92-01), simplified for a robot that can turn in place:

    e = wrap(atan2(g - p) - theta),    omega = clip(k_w e, +-omega_max),
    v = v_cruise * max(cos e, 0)^2     (0 when |e| > 60 deg; slowed near the end point)

The aim point is offset sideways from the centre line by an Ornstein-Uhlenbeck
process (std ``path_wander``, time constant ``wander_time``; exact discretisation
o' = a o + sigma sqrt(1 - a^2) N(0, 1), a = exp(-dt / tau)), faded out over the
first and last metre of a run so that runs start and end at the start point.

Because it steers from the true pose, a bump (the true heading turned in one step,
unseen by odometry) is corrected by the follower exactly as a real robot would be
steered back by its own navigation. Unicycle motion uses the midpoint rule of
fuzzyslam.robot.motion_step, so the encoder increments describe the motion exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fuzzyslam.se2 import wrap_angle_scalar
from fuzzyslam.sim.params import Bump, RobotParams, ScenarioParams
from fuzzyslam.sim.world import Loop, loop_length, point_at
from fuzzyslam.streams.logmeta import Event

K_OMEGA = 2.0
STOP_DISTANCE = 0.03
ALIGNED = math.radians(0.25)
SEARCH = np.arange(-0.3, 0.5001, 0.02)


@dataclass
class Drive:
    """True motion at the robot rate: times (N+1,), poses (N+1, 3), increments (N,) each.

    ``d_trans[k], d_rot[k]`` move pose k to pose k+1 (midpoint rule); a bump adds
    ``bump[k]`` to the heading on top of that, unseen by the wheels.
    """

    t: np.ndarray
    pose: np.ndarray
    d_trans: np.ndarray
    d_rot: np.ndarray
    bump: np.ndarray
    events: list[Event] = field(default_factory=list)

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0]) if len(self.t) > 1 else 0.0

    @property
    def duration(self) -> float:
        return float(self.t[-1])


def start_pose(centre: np.ndarray, scenario: ScenarioParams) -> np.ndarray:
    """Start pose on the centre line, facing forward along it.

    Parameters
    ----------
    centre : ndarray, shape (N, 2)
        The centre-line loop.
    scenario : ScenarioParams
        Where on it the robot starts.

    Returns
    -------
    ndarray, shape (3,)
    """
    p, tang = point_at(centre, np.array([scenario.start_offset]))
    return np.array([p[0, 0], p[0, 1], math.atan2(tang[0, 1], tang[0, 0])])


def drive(
    centre: np.ndarray,
    robot: RobotParams,
    scenario: ScenarioParams,
    rng: np.random.Generator | None = None,
    max_duration: float = 36000.0,
) -> Drive:
    """Drive the runs of ``scenario`` around the centre-line loop ``centre`` (N, 2).

    Without ``rng`` the aim point stays on the centre line (no wander).

    Parameters
    ----------
    centre : ndarray, shape (N, 2)
        The centre-line loop.
    robot : RobotParams
        Speeds and control rate.
    scenario : ScenarioParams
        The runs, bumps and wander.
    rng : numpy.random.Generator, optional
        The path's random stream.
    max_duration : float
        Longest drive (s).

    Returns
    -------
    Drive
        True poses, increments and events.
    """
    dt = 1.0 / robot.rate_hz
    lap = loop_length(centre) * scenario.lap_fraction
    s0 = scenario.start_offset
    bumps: dict[int, list[Bump]] = {}
    for bp in sorted(scenario.bumps, key=lambda bp: (bp.run, bp.fraction)):
        bumps.setdefault(bp.run, []).append(bp)
    pose = start_pose(centre, scenario)
    loop = Loop(centre)
    x, y, th = (float(v) for v in pose)
    ts, poses, dts, drs, bmp = [0.0], [(x, y, th)], [], [], []
    events = [Event(t=0.0, kind="run_start", run=1, direction=1)]
    run, direction, sigma, turning, n_bumped = 1, 1, 0.0, False, 0
    v_max = min(robot.cruise_speed, robot.max_speed)
    a_ou = math.exp(-dt / robot.wander_time)
    b_ou = robot.path_wander * math.sqrt(1.0 - a_ou * a_ou) if rng is not None else 0.0
    offset = 0.0
    k = 0
    while True:
        t = k / robot.rate_hz
        if t > max_duration:
            raise RuntimeError(f"the drive did not finish within {max_duration} s")
        v = w = 0.0
        if turning:
            g0, g1, _, _ = loop.at1(s0 + direction * (sigma + robot.lookahead))
            e = wrap_angle_scalar(math.atan2(g1 - y, g0 - x) - th)
            if abs(e) < ALIGNED:
                turning = False
                events.append(Event(t=t, kind="run_start", run=run, direction=direction))
            else:
                w = max(-robot.max_turn_rate, min(robot.max_turn_rate, K_OMEGA * e))
        if not turning:
            cand = np.clip(sigma + SEARCH, 0.0, lap)
            pts, _ = loop.at(s0 + direction * cand)
            sigma = float(cand[np.argmin(np.hypot(pts[:, 0] - x, pts[:, 1] - y))])
            end0, end1, _, _ = loop.at1(s0 + direction * lap)
            to_end = math.hypot(end0 - x, end1 - y)
            if lap - sigma < 0.5 and to_end < STOP_DISTANCE:
                events.append(Event(t=t, kind="run_end", run=run))
                if run == scenario.runs:
                    break
                run, direction, sigma, turning, n_bumped = run + 1, -direction, 0.0, True, 0
                s0 = s0 + (-direction) * lap
                k += 1
                ts.append(k / robot.rate_hz)
                poses.append((x, y, th))
                dts.append(0.0)
                drs.append(0.0)
                bmp.append(0.0)
                continue
            s_aim = min(sigma + robot.lookahead, lap)
            g0, g1, tg0, tg1 = loop.at1(s0 + direction * s_aim)
            if rng is not None:
                offset = a_ou * offset + b_ou * float(rng.standard_normal())
            fade = min(1.0, sigma, max(lap - s_aim, 0.0))
            gx = g0 - direction * tg1 * offset * fade
            gy = g1 + direction * tg0 * offset * fade
            e = wrap_angle_scalar(math.atan2(gy - y, gx - x) - th)
            w = max(-robot.max_turn_rate, min(robot.max_turn_rate, K_OMEGA * e))
            v = 0.0 if abs(e) > math.pi / 3 else v_max * max(math.cos(e), 0.0) ** 2
            if lap - sigma < robot.lookahead:
                v = min(v, 0.8 * to_end + 0.01)
        d_trans, d_rot = v * dt, w * dt
        th_mid = th + 0.5 * d_rot
        x += d_trans * math.cos(th_mid)
        y += d_trans * math.sin(th_mid)
        th = wrap_angle_scalar(th + d_rot)
        b = 0.0
        todo = bumps.get(run, [])
        if n_bumped < len(todo) and not turning and sigma >= todo[n_bumped].fraction * lap:
            b = math.radians(todo[n_bumped].angle_deg)
            th = wrap_angle_scalar(th + b)
            n_bumped += 1
            events.append(Event(t=(k + 1) / robot.rate_hz, kind="bump", run=run, angle=b))
        k += 1
        ts.append(k / robot.rate_hz)
        poses.append((x, y, th))
        dts.append(d_trans)
        drs.append(d_rot)
        bmp.append(b)
    return Drive(
        t=np.asarray(ts),
        pose=np.asarray(poses),
        d_trans=np.asarray(dts),
        d_rot=np.asarray(drs),
        bump=np.asarray(bmp),
        events=events,
    )
