"""The recording edge: stream a simulation out to one MCAP file, in time order.

The plan (world, true drive, encoders, events) is small and computed first, so the
world and scenario metadata go at the START of the file. Then every stream is
written in log-time order: robot-rate messages (/joint_states, /odom,
/ground_truth/odom), sonar rings and camera frames, each simulated just before it
is written; nothing of the recording is held in memory but the robot-rate messages
of the next 1024 steps. Messages are CDR-encoded by ``streams/cdr_encode.py`` (the
bytes rosbags gives for the ``streams/messages.py`` builders, several times faster).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from fuzzyslam.config import config_to_dict
from fuzzyslam.progress import Progress
from fuzzyslam.robot import WHEEL_NAMES, sonar_frame, sonar_mounts
from fuzzyslam.se2 import interpolate_pose, inverse_transform_points, wrap_angle
from fuzzyslam.sim import camera as simcam
from fuzzyslam.sim import sonar as simsonar
from fuzzyslam.sim.obstacles import OBSTACLES_KEY, box_segments, discs_at, obstacles_record
from fuzzyslam.sim.scenario import Plan, lamps_lit, make_plan, rng_streams
from fuzzyslam.streams import cdr_encode as E
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.logmeta import SCENARIO_KEY, WORLD_KEY, Scenario, World
from fuzzyslam.streams.typestore import serialize
from fuzzyslam.streams.writer import LogWriter

CAMERA_FRAME = "ceiling_camera"
ROBOT, SONAR, CAMERA, EVENT = 1, 2, 3, 0  # write order of messages sharing a stamp


@dataclass
class Stats:
    """Figures gathered while recording."""

    frames: int = 0
    frames_two_lamps: int = 0
    frames_all_on: int = 0
    frames_two_lamps_all_on: int = 0
    rings: int = 0
    no_echo: int = 0
    lamps_in_view: list[int] = field(default_factory=list)


def sensor_times(rate_hz: float, duration: float) -> np.ndarray:
    """Times j / rate for j = 0, 1, ... up to the duration.

    Parameters
    ----------
    rate_hz : float
        The sensor's rate.
    duration : float
        The drive's duration (s).

    Returns
    -------
    ndarray, shape (N,)
    """
    n = int(np.floor(duration * rate_hz + 1e-9)) + 1
    return np.arange(n) / rate_hz


def sonar_firings(params, duration: float, source: str = "config") -> np.ndarray:
    """Firing times (K, M) of the sonars: ring k's sonar j fires at k / rate + j * gap
    (``sonar.firing_gap_s``; 0: the whole ring at once), the rings whose last sonar fires
    after the drive left out.

    Parameters
    ----------
    params : SonarParams
        The ring (count, rate, firing gap).
    duration : float
        The drive's duration (s).
    source : str
        The config's name (for the error message).

    Returns
    -------
    ndarray, shape (K, M)

    Raises
    ------
    ConfigError
        When a ring's sonars would still fire as the next ring starts, or over more than
        a ring is read as (``streams.sonar.MAX_RING_SPAN_S``).
    """
    from fuzzyslam.errors import ConfigError
    from fuzzyslam.streams.sonar import MAX_RING_SPAN_S

    span = params.firing_gap_s * (params.count - 1)
    if span * params.rate_hz >= 1.0 or span >= MAX_RING_SPAN_S:
        raise ConfigError(
            source,
            f"sonar.firing_gap_s {params.firing_gap_s} s: a ring of {params.count} sonars "
            f"would fire for {span:.3f} s, longer than its period 1 / sonar.rate_hz = "
            f"{1.0 / params.rate_hz:.3f} s or than a firing cycle is read as one ring "
            f"({MAX_RING_SPAN_S} s)",
        )
    fire = sensor_times(params.rate_hz, duration)[:, None] + params.firing_gap_s * np.arange(
        params.count
    )
    return fire[fire[:, -1] <= duration + 1e-9]


def world_markers(world: World, lamp_z: float) -> object:
    """/sim/world MarkerArray: walls as one LINE_LIST, lamps as CYLINDERs.

    Parameters
    ----------
    world : World
        The simulated world.
    lamp_z : float
        The lamps' height (m).

    Returns
    -------
    MarkerArray
    """
    walls = world.wall_array
    pts = walls.reshape(-1, 2)
    markers = [
        M.marker(0.0, "map", "walls", 0, 5, scale=(0.05, 0, 0), rgba=(0.2, 0.2, 0.2, 1), points=pts)
    ]
    d = 2.0 * world.lamp_radius
    for i, (x, y) in enumerate(world.lamp_array):
        markers.append(
            M.marker(
                0.0, "map", "lamps", i, 3, pose=(x, y, 0.0), z=lamp_z,
                scale=(d, d, 0.05), rgba=(1.0, 0.85, 0.1, 1.0),
            )
        )  # fmt: skip
    return M.marker_array(markers)


def static_transforms(cfg, mounts: np.ndarray) -> object:
    """/tf_static: base_link -> sonar_NN and -> ceiling_camera.

    Parameters
    ----------
    cfg : Config
        The simulation's config (camera mount).
    mounts : ndarray, shape (M, 3)
        The sonars' poses on the robot.

    Returns
    -------
    TFMessage
    """
    tfs = [
        M.transform_stamped(
            0.0, "base_link", sonar_frame(i), m[0], m[1], cfg.sonar.mount_height, m[2]
        )
        for i, m in enumerate(mounts)
    ]
    off = cfg.camera.offset
    tfs.append(
        M.transform_stamped(
            0.0, "base_link", CAMERA_FRAME, off[0], off[1], cfg.camera.mount_height, 0.0
        )
    )
    return M.tf_message(tfs)


def schedule(plan: Plan, sonar: np.ndarray, camera_rate: float) -> list[tuple[float, int, int]]:
    """(t, kind, index) of everything to write, in log-time order.

    Parameters
    ----------
    plan : Plan
        The simulation's plan.
    sonar : ndarray, shape (K,) or (K * M,)
        The sonar messages' times: one per ring (fired at once), or one per reading
        (fired in sequence: ring k's sonar j has index k * M + j).
    camera_rate : float
        Frames per second.

    Returns
    -------
    list of (float, int, int)
    """
    T = plan.drive.duration
    parts = [
        (plan.drive.t, ROBOT),
        (sonar, SONAR),
        (sensor_times(camera_rate, T), CAMERA),
        (np.array([e.t for e in plan.events]), EVENT),
    ]
    t = np.concatenate([p[0] for p in parts])
    kind = np.concatenate([np.full(len(p[0]), p[1]) for p in parts])
    idx = np.concatenate([np.arange(len(p[0])) for p in parts])
    order = np.lexsort((idx, kind, t))
    return list(zip(t[order].tolist(), kind[order].tolist(), idx[order].tolist(), strict=True))


def write_truth_tum(plan: Plan, path: str | os.PathLike) -> None:
    """The true trajectory of a simulation (the poses of /ground_truth/odom, at the robot
    rate) as a TUM file (``streams.tum.format_tum``), written atomically: the truth evo
    and ``evaluate`` read, beside the log.

    Parameters
    ----------
    plan : Plan
        The simulation's plan.
    path : path
        The TUM file.
    """
    from fuzzyslam.fileio import atomic_path
    from fuzzyslam.streams.tum import format_tum

    with atomic_path(path) as tmp:
        Path(tmp).write_text(format_tum(plan.drive.t, plan.drive.pose), encoding="utf-8")


def robot_payloads(
    plan: Plan, wheels: tuple[str, str] = WHEEL_NAMES, block: int = 1024
) -> Iterator[tuple[bytes, bytes, bytes, bytes]]:
    """CDR of (/joint_states, /odom, /ground_truth/odom, /tf) at every robot step, in
    order, encoded ``block`` steps at a time: the wheel angles, the dead reckoning and the
    true pose, with the velocities of the step before (0 at the first), and the dead
    reckoning as the transform odom -> base_link, as a robot's driver broadcasts it (REP
    105), so that the sonars and the camera of /tf_static sit in the odom frame (and, with
    a run's estimates.mcap and its map -> odom, in the map).

    Parameters
    ----------
    plan : Plan
        The simulation's plan.
    wheels : (str, str)
        The wheels' joint names (``robot.left_wheel_joint``, ``right_wheel_joint``).
    block : int
        Steps encoded at once.

    Returns
    -------
    iterator of (bytes, bytes, bytes, bytes)
    """
    dr, enc = plan.drive, plan.encoders
    n, dt = len(dr.t), dr.dt
    first = np.zeros(1)
    v_odo = np.concatenate([first, enc.d_trans[: n - 1] / dt])
    w_odo = np.concatenate([first, enc.d_rot[: n - 1] / dt])
    v_true = np.concatenate([first, dr.d_trans[: n - 1] / dt])
    w_true = np.concatenate([first, dr.d_rot[: n - 1] / dt])
    for a in range(0, n, block):
        k = slice(a, min(a + block, n))
        t = dr.t[k]
        yield from zip(
            E.encode_joint_state_block(t, wheels, enc.angles[k]),
            E.encode_odometry_block(t, "odom", "base_link", enc.dead_reckoning[k], v_odo[k],
                                    w_odo[k]),
            E.encode_odometry_block(t, "map", "base_link", dr.pose[k], v_true[k], w_true[k]),
            E.encode_tf_block(t, [("odom", "base_link")], [enc.dead_reckoning[k]]),
            strict=True,
        )  # fmt: skip


RING_BLOCK = 32  # sonar rings traced together


def _ideal_block(dr, fire: np.ndarray, walls, mounts, params, obstacles=()) -> np.ndarray:
    """Ideal ranges (K', M) of the first K' <= K rings fired at ``fire`` (K, M) from the
    true drive: the rings that meet the same obstacles as the first (boxes reflect like
    walls, people are discs; ``sim.obstacles``, those present at the ring's first
    firing), so that they share the walls and their numbers of people. Each sonar is
    traced from the robot's pose, and the people where they are, at its own firing time
    (one time per ring when the ring fires at once).
    """
    times = fire[:, 0]
    if obstacles:
        there = [tr.present(times[0]) for tr in obstacles]
        k = next((j for j, t in enumerate(times.tolist())
                  if [tr.present(t) for tr in obstacles] != there), len(times))  # fmt: skip
        times, fire = times[:k], fire[:k]
    discs = None
    if obstacles:
        walls = np.vstack([walls, box_segments(obstacles, times[0])])
        if params.firing_gap_s == 0.0:
            people = np.stack([discs_at(obstacles, t) for t in times.tolist()])
        else:  # (K, M, J, 3): each sonar's people where they are as it fires
            people = np.stack([
                np.stack([discs_at(obstacles, t, row[0]) for t in row]) for row in fire.tolist()
            ])  # fmt: skip
        discs = people if people.shape[-2] else None
    if params.firing_gap_s == 0.0:
        poses = np.array([interpolate_pose(dr.t, dr.pose, t) for t in times.tolist()])
        return simsonar.ideal_ranges_many(walls, poses.reshape(-1, 3), mounts, params, discs)
    poses = np.array([interpolate_pose(dr.t, dr.pose, t) for t in fire.ravel().tolist()])
    return simsonar.ideal_ranges_many(walls, poses.reshape((*fire.shape, 3)), mounts, params,
                                      discs)  # fmt: skip


def simulate_to_mcap(cfg, out: str | os.PathLike, source: str = "config") -> tuple[dict, Plan]:
    """Simulate ``cfg`` and write the recording to ``out`` (atomic): (summary, plan).

    Parameters
    ----------
    cfg : Config
        The simulation's config.
    out : path
        The MCAP file.
    source : str
        The config's name (for error messages).

    Returns
    -------
    summary : dict
        The recording's figures (the JSON summary's part).
    plan : Plan
    """
    rngs = rng_streams(cfg.seed)
    plan = make_plan(cfg, rngs, source)
    world, dr, enc = plan.world, plan.drive, plan.encoders
    robot = robot_payloads(plan, cfg.robot.wheel_joints)
    topics = cfg.topics
    mounts = sonar_mounts(cfg.sonar.count, cfg.robot.radius)
    cam = simcam.make_camera(cfg.camera)
    bg = simcam.background(cam, cfg.camera)
    walls = world.wall_array
    lamps = world.lamp_array
    radius_px = cam.radius_px(world.lamp_radius)
    fov = np.radians(cfg.sonar.fov_deg)
    scenario = Scenario(
        name=cfg.name,
        seed=int(cfg.seed),
        start_pose=[float(v) for v in plan.start_pose],
        duration=dr.duration,
        events=plan.events,
        # the simulation's config: the output format (its rosbag2 record says which) is
        # not part of it, so a Humble log is what it was before the choice
        config={k: v for k, v in config_to_dict(cfg).items() if k != "output"},
    )
    sonar_topics = [topics.sonar(i) for i in range(cfg.sonar.count)]
    sonar_types = [M.RANGE] * cfg.sonar.count
    robot_topics = [topics.joint_states, topics.odom, topics.ground_truth, topics.tf]
    robot_types = [M.JOINT_STATE, M.ODOMETRY, M.ODOMETRY, M.TF_MESSAGE]  # robot_payloads'
    frames = [sonar_frame(i) for i in range(cfg.sonar.count)]
    st = Stats()
    lit = np.ones(len(lamps), dtype=bool)
    fire = sonar_firings(cfg.sonar, dr.duration, source)  # (K, M)
    sequential = cfg.sonar.firing_gap_s > 0.0  # one message per reading, at its time
    m_sonars, i0, ideal, r = cfg.sonar.count, 0, np.zeros((0, 0)), np.zeros(0)
    distro = cfg.output.ros_distro
    writer = LogWriter(out, latched=topics.latched(), ros_distro=distro)
    with writer as w, Progress(dr.duration, "simulate") as bar:
        w.json_metadata(WORLD_KEY, world.to_dict())
        w.json_metadata(SCENARIO_KEY, scenario.to_dict())
        if plan.obstacles:
            # the tracks at the rings' times as a run sees them (the last sonar's firing)
            w.json_metadata(OBSTACLES_KEY, obstacles_record(plan.obstacles, fire[:, -1]))
        w.write(topics.tf_static, M.TF_MESSAGE, static_transforms(cfg, mounts), 0.0)
        lamp_z = cfg.camera.mount_height + cfg.camera.ceiling_height
        w.write(topics.world_markers, M.MARKER_ARRAY, world_markers(world, lamp_z), 0.0)
        info = M.camera_info(0.0, CAMERA_FRAME, cam.width, cam.height_px, cam.f, cam.cx, cam.cy)
        info_cdr = serialize(info, M.CAMERA_INFO, distro)
        w.write_cdr(topics.camera_info, M.CAMERA_INFO, info_cdr, 0.0)
        sonar_t = fire.ravel() if sequential else fire[:, 0]
        for t, kind, i in schedule(plan, sonar_t, cfg.camera.rate_hz):
            if kind == EVENT:
                ev = plan.events[i]
                w.write(topics.events, M.STRING, M.json_msg(asdict(ev)), t)
                lit = lamps_lit(plan.events, len(lamps), t)
            elif kind == ROBOT:  # step i: the robot payloads come in step order
                w.write_cdr_at(robot_topics, robot_types, next(robot), t)
                bar.update_to(t)
            elif kind == SONAR:
                ring, j = divmod(i, m_sonars) if sequential else (i, 0)
                if j == 0:  # a ring's first sonar: the ring's readings drawn
                    # the ideal ranges of up to RING_BLOCK rings at a time (the same
                    # floats as ring by ring: simsonar.ideal_ranges_many)
                    if not i0 <= ring < i0 + len(ideal):
                        i0, ideal = ring, _ideal_block(dr, fire[ring : ring + RING_BLOCK],
                                                       walls, mounts, cfg.sonar,
                                                       plan.obstacles)  # fmt: skip
                    r = simsonar.measure(ideal[ring - i0], cfg.sonar, rngs["sonar"])
                    st.rings += 1
                    st.no_echo += int(np.sum(r >= cfg.sonar.max_range))
                k = slice(j, j + 1) if sequential else slice(None)
                cdrs = E.encode_ranges(t, frames[k], r[k], fov, cfg.sonar.min_range,
                                       cfg.sonar.max_range,
                                       simsonar.reading_variance(r[k], cfg.sonar),
                                       distro)  # fmt: skip
                w.write_cdr_at(sonar_topics[k], sonar_types[k], cdrs, t)
            else:
                pose = interpolate_pose(dr.t, dr.pose, t)
                rel = inverse_transform_points(pose, lamps[lit])
                img = simcam.render(cam, rel, world.lamp_radius, cfg.camera, bg, rngs["camera"])
                w.write_cdr(topics.image, M.IMAGE, E.encode_image_mono8(t, CAMERA_FRAME, img), t)
                if i > 0:
                    w.write_cdr(topics.camera_info, M.CAMERA_INFO, E.restamp(info_cdr, t), t)
                n_vis = int(np.sum(simcam.visible(cam, cam.project(rel), radius_px)))
                st.frames += 1
                st.frames_two_lamps += n_vis >= 2
                st.lamps_in_view.append(n_vis)
                if lit.all():
                    st.frames_all_on += 1
                    st.frames_two_lamps_all_on += n_vis >= 2
        counts = dict(sorted(w.counts.items()))
    err = enc.dead_reckoning - dr.pose
    pos_err = np.hypot(err[:, 0], err[:, 1])
    summary = {
        "file": str(Path(out)),
        "name": cfg.name,
        "seed": int(cfg.seed),
        "duration_s": round(dr.duration, 3),
        "runs": int(cfg.scenario.runs),
        "events": len(plan.events),
        "messages": counts,
        "messages_total": int(sum(counts.values())),
        "file_size_bytes": Path(out).stat().st_size,
        "dead_reckoning_end_error_m": round(float(pos_err[-1]), 4),
        "dead_reckoning_max_error_m": round(float(pos_err.max()), 4),
        "dead_reckoning_end_heading_error_deg": round(
            float(np.degrees(abs(wrap_angle(err[-1, 2])))), 3
        ),
        "frames": st.frames,
        "frames_two_lamps_fraction": round(st.frames_two_lamps / max(st.frames, 1), 4),
        "frames_two_lamps_fraction_all_lamps_on": round(
            st.frames_two_lamps_all_on / max(st.frames_all_on, 1), 4
        ),
        "lamps_in_view_mean": round(float(np.mean(st.lamps_in_view)) if st.frames else 0.0, 3),
        "sonar_no_echo_fraction": round(st.no_echo / max(st.rings * cfg.sonar.count, 1), 4),
    }
    return summary, plan
