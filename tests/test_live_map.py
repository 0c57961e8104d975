"""``run --live-map``: the map built while localising on it (fixes/live_map.py).

The pure parts against second implementations (a growing map against one map of the
whole extent, the live matcher against the frozen one on a copy of the same map, the
end points and the building's direction against their geometry); the command on the
committed real excerpt (data/carmen_fr079_excerpt: 60 s of CARMEN Freiburg 079) against
its truth and its dead reckoning; the full CARMEN logs (slow, skipped without
../shared).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli
from maps_synth import ring_in_lines, room_lines

from fuzzyslam.config import load_config
from fuzzyslam.fixes.live_map import (
    LiveFgm,
    LiveMatcher,
    building_direction,
    end_points,
    grown_grid,
)
from fuzzyslam.fixes.pose_match import PoseMatcher
from fuzzyslam.maps.fgm import FgmBuilder
from fuzzyslam.maps.grid import BeliefMap, Grid
from fuzzyslam.se2 import interpolate_poses, wrap_angle
from fuzzyslam.slam.odom_gate import first_plausible_pose
from fuzzyslam.streams.tum import read_tum

ROOT = Path(__file__).resolve().parents[1]
EXCERPT = ROOT / "data" / "carmen_fr079_excerpt"
SHARED = ROOT.parent / "shared" / "data" / "real"

# a laser of 90 beams over 180 deg, 2-deg cones (the scan preset's), 20 m
BEAMS = np.linspace(-math.pi / 2, math.pi / 2, 90)
MOUNTS = np.stack([np.full(90, 0.1), np.zeros(90), BEAMS], axis=1)
FOV = math.radians(2.0)
RMAX = 20.0


def laser_ring(pose, lines) -> np.ndarray:
    """Analytic ranges of the laser at ``pose`` in the walls ``lines`` (maps_synth)."""
    return ring_in_lines(np.asarray(pose, float), MOUNTS, lines, FOV, RMAX)


def test_grown_grid_covers_the_box_on_the_same_cells():
    g = Grid((-1.0, -2.0), 0.1, (40, 30))  # x in [-1, 2), y in [-2, 2)
    assert grown_grid(g, np.array([-0.5, -1.0]), np.array([1.5, 1.0]), 5.0) is g
    h = grown_grid(g, np.array([-3.05, -1.0]), np.array([1.5, 2.5]), 5.0)
    ox, oy = h.origin
    # grown by whole cells, at least 5 m on each side that had to grow, none elsewhere
    assert (ox - g.origin[0]) / 0.1 == pytest.approx(round((ox - g.origin[0]) / 0.1))
    assert ox <= -3.05 - 5.0 + 1e-9 and oy == g.origin[1]
    assert oy + h.shape[0] * 0.1 >= 2.5 + 5.0 - 1e-9
    assert ox + h.shape[1] * 0.1 == pytest.approx(2.0)  # the right side did not grow


def test_a_growing_map_holds_what_one_map_of_the_whole_extent_holds():
    """Rings fused into a LiveFgm that grows three times: the same masses, cell for cell
    in the world, as FgmBuilder on one grid covering everything from the start."""
    params = load_config("real_building_scan").fgm
    lines = room_lines(-3.0, -2.0, 60.0, 3.0)  # a long hall: the robot leaves the first grid
    poses = np.array([[x, 0.2 * math.sin(x / 5), 0.02 * x] for x in np.arange(0.0, 55.0, 1.5)])
    live = LiveFgm(poses[0], params)
    whole = FgmBuilder(Grid.covering(-40.0, -40.0, 100.0, 40.0, params.resolution), params)
    for p in poses:
        r = laser_ring(p, lines)
        live.add_ring(p, r, RMAX, FOV, MOUNTS)
        whole.add_ring(p, r, RMAX, FOV, MOUNTS)
    assert live.grown >= 2
    g, w = live.map.grid, whole.map.grid
    r0 = round((g.origin[1] - w.origin[1]) / g.resolution)
    c0 = round((g.origin[0] - w.origin[0]) / g.resolution)
    ny, nx = g.shape
    for a, b in (("m_o", "m_o"), ("m_e", "m_e"), ("m_t", "m_t"), ("m_c", "m_c")):
        np.testing.assert_allclose(
            getattr(live.map, a), getattr(whole.map, b)[r0 : r0 + ny, c0 : c0 + nx], atol=1e-6
        )
    assert float(whole.map.m_o.sum()) == pytest.approx(float(live.map.m_o.sum()), rel=1e-5)
    total = live.map.m_e + live.map.m_o + live.map.m_t + live.map.m_c
    np.testing.assert_allclose(total, 1.0, atol=1e-5)


def test_the_live_matcher_matches_as_the_frozen_one_on_a_copy():
    """LiveMatcher reads the patch's lookup from the live masses: its match of a template
    equals PoseMatcher's on a frozen copy of the same map (pose and covariance)."""
    cfg = load_config("real_building_scan")
    lines = room_lines(-4.0, -3.0, 9.0, 2.5)
    live = LiveFgm(np.zeros(3), cfg.fgm)
    for p in ([0, 0, 0], [2, 0.3, 0.4], [5, -0.5, -0.3], [7, 0.5, 2.0]):
        live.add_ring(p, laser_ring(p, lines), RMAX, FOV, MOUNTS)
    m = live.map
    frozen = PoseMatcher(BeliefMap(m.grid, m.m_e.copy(), m.m_o.copy(), m.m_t.copy(),
                                   m.m_c.copy()), cfg.fixes)  # fmt: skip
    moving = LiveMatcher(live, cfg.fixes)
    true = np.array([3.2, 0.1, 0.25])
    pts, masses = end_points(laser_ring(true, lines), RMAX, MOUNTS, 12.0)
    guess = true + np.array([0.12, -0.08, math.radians(2.0)])
    cov = np.diag([0.1**2, 0.1**2, math.radians(3.0) ** 2])
    a = frozen.match_points(pts, masses, guess, cov, 1.0)
    b = moving.match_points(pts, masses, guess, cov, 1.0)
    assert a.ok and b.ok
    np.testing.assert_allclose(b.pose, a.pose, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.cov, a.cov, rtol=1e-9, atol=1e-15)
    # and it finds the pose: within two cells and a degree of the truth
    assert np.hypot(*(b.pose[:2] - true[:2])) < 0.2
    assert abs(wrap_angle(b.pose[2] - true[2])) < math.radians(1.0)


def test_end_points_are_where_the_echoes_are():
    mounts = np.array([[0.1, 0.0, 0.0], [0.1, 0.0, math.pi / 2], [0.0, 0.2, math.pi], [0, 0, 0]])
    ranges = np.array([2.0, 1.0, 20.0, np.nan])  # the third: no echo (its max range)
    pts, masses = end_points(ranges, np.array([20.0, 20.0, 20.0, 20.0]), mounts, 5.0)
    np.testing.assert_allclose(pts, [[2.1, 0.0], [0.1, 1.0]], atol=1e-12)
    np.testing.assert_array_equal(masses, [[1.0, 0.0], [1.0, 0.0]])
    pts, _ = end_points(ranges, 20.0, mounts, 1.5)  # beyond the reach: left out
    np.testing.assert_allclose(pts, [[0.1, 1.0]], atol=1e-12)


def test_building_direction_is_the_walls_direction_modulo_right_angles():
    rng = np.random.default_rng(3)
    for true in (0.0, 0.3, 1.2, math.radians(89.5)):
        k = rng.integers(-4, 5, 60)
        ang = true + k * math.pi / 2 + rng.normal(0.0, math.radians(1.0), 60)
        lengths = rng.uniform(0.5, 4.0, 60)
        # a few walls at 45 deg (a slanted room): light, they move the mean little
        ang = np.concatenate([ang, true + math.pi / 4 + np.zeros(3)])
        lengths = np.concatenate([lengths, np.full(3, 0.5)])
        got = building_direction(ang, lengths)
        assert 0.0 <= got < math.pi / 2
        d = (got - true + math.pi / 4) % (math.pi / 2) - math.pi / 4
        assert abs(d) < math.radians(0.5)


def _errors(traj: Path, truth: Path) -> np.ndarray:
    """Position errors (m) of a trajectory against truth, at the trajectory's stamps."""
    t, p = read_tum(traj)
    tt, pt = read_tum(truth, sort=True)
    inside = (t >= tt[0]) & (t <= tt[-1])
    q = interpolate_poses(tt, pt, t[inside])
    return np.hypot(*(p[inside, :2] - q[:, :2]).T)


@pytest.mark.slow
def test_live_map_on_a_real_building_beats_dead_reckoning(tmp_path, capsys):
    """60 s of Freiburg 079, its laser, no map and no lamps: the live map localises
    within half the dead reckoning's mean error (measured 0.16 m against 0.37 m), learns
    the building's direction and fixes the heading with it, and shows the map in
    estimates.mcap; its trajectory builds the frozen map (``map --trajectory``), on
    which pose fixes localise the log again (measured 0.21 m)."""
    log, truth = EXCERPT / "log.mcap", EXCERPT / "truth.tum"
    tt, pt = read_tum(truth)
    start = ",".join(f"{v:.6f}" for v in first_plausible_pose(tt, pt)[1])
    out, dr = tmp_path / "live", tmp_path / "dr"
    code, s, err = run_cli(
        ["run", str(log), "--config", "real_building_scan", "--live-map",
         f"--start-pose={start}", "-o", str(out)], capsys,
    )  # fmt: skip
    assert code == 0, err
    assert "trajectory_closed.tum has its loops closed" in err  # the run's note: what to map from
    live = s["aids"]["LiveMapPoseAid"]
    assert live["keyframes"] >= 20 and live["accepted"] >= 20
    assert live["map_resolution_m"] == 0.1 and len(live["map_shape"]) == 2
    heading = s["aids"]["LiveRightAngleHeading"]
    assert heading["accepted"] > 20 and heading["reference_learnt_at"] is not None
    # a right-angled building: its scans' wall families meet square, nothing said
    assert heading["off_right_angles_at"] is None and heading["off_right_angle_scans"] == 0
    assert "right angles" not in err
    assert s["filter_health"]["reasons"] == []
    assert (out / "pose_fixes.csv").is_file() and (out / "heading_fixes.csv").is_file()
    # the events made in one process or in a child (the default on two cores): the same files
    one = tmp_path / "one"
    code, _, err = run_cli(
        ["run", str(log), "--config", "real_building_scan", "--live-map", "--no-prefetch",
         f"--start-pose={start}", "-o", str(one)], capsys,
    )  # fmt: skip
    assert code == 0, err
    names = ("trajectory.tum", "trajectory_closed.tum", "pose_fixes.csv", "heading_fixes.csv",
             "estimates.mcap")  # fmt: skip
    for name in names:
        assert (one / name).read_bytes() == (out / name).read_bytes(), name
    code, _, err = run_cli(["run", str(log), f"--start-pose={start}", "-o", str(dr)], capsys)
    assert code == 0, err
    e_live, e_dr = _errors(out / "trajectory.tum", truth), _errors(dr / "trajectory.tum", truth)
    assert e_live.mean() < 0.5 * e_dr.mean()
    # 60 s hold no loop: the closed trajectory is the keyframe graph's smoothing, as good
    assert live["loop_closure"]["loops"] == 0
    assert _errors(out / "trajectory_closed.tum", truth).mean() < 0.5 * e_dr.mean()
    from fuzzyslam.streams.reader import LogReader

    assert LogReader(out / "estimates.mcap").has(load_config("real_building_scan").topics.map)
    # the pipeline on: the closed live trajectory builds the FGM, pose fixes on it
    fgm, pose = tmp_path / "fgm", tmp_path / "pose"
    code, m, err = run_cli(
        ["map", str(log), "--trajectory", str(out / "trajectory_closed.tum"), "--config",
         "real_building_scan", "-o", str(fgm)], capsys,
    )  # fmt: skip
    assert code == 0, err
    assert m["references"], "no corridor found in the live map's FGM"
    code, _, err = run_cli(
        ["run", str(log), "--config", "real_building_scan", "--map", str(fgm), "--fix",
         "pose", "--fix-from", "0", f"--start-pose={start}", "-o", str(pose)], capsys,
    )  # fmt: skip
    assert code == 0, err
    # the map holds the live run's errors: localised on it, as near the truth as the live
    # run was (measured 0.21 m against 0.16 m), well within the dead reckoning's 0.37 m
    e_pose = _errors(pose / "trajectory.tum", truth)
    assert e_pose.mean() < e_live.mean() + 0.1 and e_pose.mean() < 0.75 * e_dr.mean()


@pytest.mark.parametrize(
    "extra, says",
    [
        (["--map", "somewhere"], "takes no --map"),
        (["--fix", "heading"], "--fix heading"),
        (["--fix-from", "0"], "--fix-from"),
    ],
)
def test_live_map_refuses_what_does_not_go_with_it(extra, says, tmp_path, capsys):
    code, _, err = run_cli(
        ["run", str(EXCERPT / "log.mcap"), "--live-map", *extra, "-o", str(tmp_path / "o")],
        capsys,
    )
    assert code == 2 and says in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
@pytest.mark.parametrize("building", ["carmen-aces", "carmen-fr079"])
def test_live_map_on_whole_buildings(building, tmp_path, capsys):
    """The whole CARMEN logs (laser): the live map, its loops closed during the run, has
    a median position error under a third of the dead reckoning's (measured means: ACES
    0.48 m against 5.42 m, Freiburg 0.20 m against 1.16 m), the loops closed again after
    it lower it again, and its median heading error is under 1.5 deg (1.0 and 0.9 deg
    mean). ACES's big loop comes back off its first walls: filter_health may say
    nis_rate there (docs/models.md sec. 10b), so it is not asserted."""
    d = SHARED / building
    if not (d / "log.mcap").is_file():
        pytest.skip("the CARMEN logs are not here (../shared/data/real)")
    out, dr = tmp_path / "live", tmp_path / "dr"
    code, s, err = run_cli(
        ["run", str(d / "log.mcap"), "--config", "real_building_scan", "--live-map",
         "-o", str(out)], capsys,
    )  # fmt: skip
    assert code == 0, err
    # loops closed during the run (measured: ACES 15, Freiburg 80), and said so
    loops = s["aids"]["LiveMapPoseAid"]["loop_closure"]
    assert loops["online_closures"] >= 3 and loops["online_moved_max_m"] >= 0.1
    assert f"{loops['online_closures']} loops closed during the run" in err
    # real right-angled buildings: no scan's wall families meet more than 3 deg off a
    # right angle (measured: 0 of 2 on ACES, 0 of 114 on Freiburg), nothing said
    heading = s["aids"]["LiveRightAngleHeading"]
    assert heading["off_right_angles_at"] is None and heading["off_right_angle_scans"] == 0
    assert run_cli(["run", str(d / "log.mcap"), "-o", str(dr)], capsys)[0] == 0
    e_live = _errors(out / "trajectory.tum", d / "truth.tum")
    e_dr = _errors(dr / "trajectory.tum", d / "truth.tum")
    assert np.median(e_live) < np.median(e_dr) / 3
    # the loops closed after the run: nearer the truth again (measured means: ACES
    # 0.48 -> 0.37 m, Freiburg 0.20 -> 0.14 m)
    e_closed = _errors(out / "trajectory_closed.tum", d / "truth.tum")
    assert np.median(e_closed) < 0.85 * np.median(e_live)
    t, p = read_tum(out / "trajectory.tum")
    tt, pt = read_tum(d / "truth.tum", sort=True)
    q = interpolate_poses(tt, pt, t[(t >= tt[0]) & (t <= tt[-1])])
    h = wrap_angle(p[(t >= tt[0]) & (t <= tt[-1]), 2] - q[:, 2])
    assert np.median(np.abs(np.degrees(h))) < 1.5


def test_live_map_needs_a_range_sensor(tmp_path, capsys):
    """A log without sonars or a laser (an MRCLAM excerpt: odometry and landmark
    detections) has nothing to map: one line naming the missing streams, exit 3, no
    output directory."""
    log = ROOT / "data" / "real" / "mrclam6_excerpt" / "log.mcap"
    code, _, err = run_cli(["run", str(log), "--live-map", "-o", str(tmp_path / "o")], capsys)
    assert code == 3 and "missing stream" in err and "/scan" in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("fov_deg, laser", [(2.0, True), (25.0, False)])
def test_only_a_lasers_matches_take_live_cov_scale(fov_deg, laser):
    """The first ring decides: a laser's (narrow beams: end points) matches are inflated
    by live_cov_scale whatever the travel; a sonar ring's FLM matches keep the frozen
    map's pose_cov_scale and pose_corr_distance (docs/models.md sec. 10b)."""
    from types import SimpleNamespace

    from fuzzyslam.fixes.live_map import LiveMapPoseAid

    cfg = load_config("real_building_scan")
    aid = LiveMapPoseAid(cfg.fixes, cfg.fgm, flm_source=None)
    ring = SimpleNamespace(
        ranges=laser_ring([0, 0, 0], room_lines(-4, -3, 9, 2.5)), max_range=RMAX,
        fov=math.radians(fov_deg),
    )  # fmt: skip
    ekf = SimpleNamespace(pose=np.zeros(3), odometry_pose=np.zeros(3))
    aid.on_ring(1.0, ring, MOUNTS, ekf)  # the first ring: fused only
    assert aid.keyframes == 1 and aid.live is not None
    p, given = aid.params, cfg.fixes
    if laser:
        assert (p.pose_cov_scale, p.pose_corr_distance) == (given.live_cov_scale, 0.0)
    else:
        assert (p.pose_cov_scale, p.pose_corr_distance) == (
            given.pose_cov_scale,
            given.pose_corr_distance,
        )
    assert p.pose_map_sigma == 0.0 and aid.matcher.params is p


def test_only_a_lasers_keyframes_are_closed():
    """closed(): None for a sonar ring's keyframes (their matches too loose for the
    graph), for live_close_loops off, and for fewer than two keyframes."""
    import dataclasses

    from fuzzyslam.fixes.live_map import Keyframe, LiveMapPoseAid

    cfg = load_config("real_building_scan")

    def frames(fov_deg: float) -> list:
        return [
            Keyframe(k, float(k), np.array([k, 0.0, 0.0]), np.array([k, 0.0, 0.0]),
                     np.full(90, 3.0), RMAX, math.radians(fov_deg), MOUNTS)
            for k in range(2)
        ]  # fmt: skip

    aid = LiveMapPoseAid(cfg.fixes, cfg.fgm, flm_source=None)
    aid._frames = frames(25.0)
    assert aid.closed() is None
    off = LiveMapPoseAid(dataclasses.replace(cfg.fixes, live_close_loops=False), cfg.fgm, None)
    off._frames = frames(2.0)
    assert off.closed() is None
    aid._frames = frames(2.0)[:1]
    assert aid.closed() is None


def test_a_live_map_too_large_is_one_clear_error(monkeypatch):
    """A path that would grow the grid past MAX_CELLS: a FuzzyslamError (one line, the
    input's exit code) naming the size and the way out, not an internal error."""
    from fuzzyslam.errors import FuzzyslamError
    from fuzzyslam.fixes import live_map

    monkeypatch.setattr(live_map, "MAX_CELLS", 200_000)
    params = load_config("real_building_scan").fgm
    live = LiveFgm(np.zeros(3), params)  # 32 x 32 m: 102 400 cells
    lines = room_lines(-3.0, -2.0, 60.0, 3.0)
    with pytest.raises(FuzzyslamError, match=r"fgm\.resolution"):
        for x in np.arange(0.0, 55.0, 1.5):
            p = np.array([x, 0.0, 0.0])
            live.add_ring(p, laser_ring(p, lines), RMAX, FOV, MOUNTS)


def test_refill_is_the_map_of_its_keyframes_fused_in_turn(monkeypatch):
    """LiveFgm.refill (an online loop closure's): in batches, from nothing, growing the
    grid, the same masses cell for cell as add_ring of each keyframe at its pose."""
    from fuzzyslam.fixes import live_map
    from fuzzyslam.fixes.live_map import Keyframe

    monkeypatch.setattr(live_map, "REFILL_BATCH", 4)
    params = load_config("real_building_scan").fgm
    lines = room_lines(-3.0, -2.0, 60.0, 3.0)
    poses = np.array([[x, 0.2 * math.sin(x / 5), 0.02 * x] for x in np.arange(0.0, 55.0, 1.5)])
    frames = [Keyframe(k, float(k), p, p, laser_ring(p, lines), RMAX, FOV, MOUNTS)
              for k, p in enumerate(poses)]  # fmt: skip
    one = LiveFgm(poses[0], params)
    for f in frames:
        one.add_ring(f.pose, f.ranges, f.max_range, f.fov, f.mounts)
    moved = LiveFgm(poses[0], params)
    for f in frames[:5]:  # a map of other poses first: refill forgets it
        moved.add_ring(f.pose + np.array([0.3, -0.2, 0.1]), f.ranges, RMAX, FOV, MOUNTS)
    moved.refill(frames)
    assert moved.builder.rings == len(frames) and moved.grown >= 2
    # both on one canvas in the world (their grids grew differently): vacuous elsewhere
    maps = (moved.map, one.map)
    lo = np.min([m.grid.origin for m in maps], axis=0)
    canvas = []
    for m in maps:
        r0, c0 = (round(v) for v in (np.asarray(m.grid.origin) - lo)[::-1] / 0.1)
        ny, nx = m.grid.shape
        c = np.zeros((4, 800, 1200))
        c[2] = 1.0  # m(Theta): nothing known
        for k, a in enumerate((m.m_e, m.m_o, m.m_t, m.m_c)):
            c[k, r0 : r0 + ny, c0 : c0 + nx] = a
        canvas.append(c)
    np.testing.assert_allclose(canvas[0], canvas[1], atol=1e-6)
    assert float(canvas[1][1].sum()) > 100.0  # walls were seen


def test_a_graph_edges_map_is_its_keyframes_fused_in_turn(monkeypatch):
    """keyframes_map (a graph edge's map): the keyframes in batches of the same sensors
    (sensor_batches: a second laser mount splits them), the same masses cell for cell
    as FgmBuilder.add_ring of each in turn at its pose relative to the anchor."""
    from fuzzyslam.fixes import live_map
    from fuzzyslam.fixes.live_map import Keyframe, keyframes_map, sensor_batches
    from fuzzyslam.maps.fgm import FgmBuilder
    from fuzzyslam.maps.grid import Grid
    from fuzzyslam.se2 import between

    monkeypatch.setattr(live_map, "REFILL_BATCH", 3)
    params = load_config("real_building_scan").fgm
    lines = room_lines(-3.0, -2.0, 30.0, 3.0)
    turned = MOUNTS + np.array([0.0, 0.05, 0.0])  # another mount: another batch
    frames = []
    for k, x in enumerate(np.arange(0.0, 12.0, 1.0)):
        p = np.array([x, 0.1 * math.sin(x), 0.03 * x])
        m = turned if k in (4, 5) else MOUNTS
        frames.append(Keyframe(k, float(k), p, p, ring_in_lines(p, m, lines, FOV, RMAX),
                               RMAX, FOV, m))  # fmt: skip
    assert [len(b) for b in sensor_batches(frames, 3)] == [3, 1, 2, 3, 3]
    anchor = frames[3].pose
    got = keyframes_map(frames, anchor, params, 8.0)
    rel = np.array([between(anchor, f.pose) for f in frames])
    lo, hi = rel[:, :2].min(axis=0) - 8.0, rel[:, :2].max(axis=0) + 8.0
    b = FgmBuilder(Grid.covering(lo[0], lo[1], hi[0], hi[1], params.resolution), params)
    for f, p in zip(frames, rel, strict=True):
        b.add_ring(p, f.ranges, f.max_range, f.fov, f.mounts)
    for x, y in zip((got.m_e, got.m_o, got.m_t, got.m_c),
                    (b.map.m_e, b.map.m_o, b.map.m_t, b.map.m_c), strict=True):  # fmt: skip
        np.testing.assert_allclose(x, y, atol=1e-6)
    assert float(got.m_o.sum()) > 50.0  # walls were seen


def _loop_scan(pose: np.ndarray, walls: np.ndarray, rmax: float) -> np.ndarray:
    """The laser's ranges at ``pose`` in the wall segments (each beam one ray; rmax: no
    echo)."""
    from fuzzyslam.se2 import compose
    from fuzzyslam.sim.sonar import cast_rays

    s = compose(np.asarray(pose, dtype=float), MOUNTS)
    d, _ = cast_rays(walls, s[:, :2], np.stack([np.cos(s[:, 2]), np.sin(s[:, 2])], axis=1))
    return np.minimum(d, rmax)


def _corridor_loop_run(online: bool) -> tuple:
    """A corridor loop of 100 m (3 m wide, a 30 x 20 m centreline), an 8 m laser, and a
    wheel slip of 0.6 m along the first corridor where no wall measures it: the live map
    built, with or without the online closure, on the real filter."""
    import dataclasses

    from fuzzyslam.fixes.live_map import LiveMapPoseAid, _RingView
    from fuzzyslam.se2 import between
    from fuzzyslam.slam.ekf import EkfSlam

    def rect(x0, y0, x1, y1):
        c = [(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]
        return [(*a, *b) for a, b in itertools.pairwise(c)]

    walls = np.array(rect(-1.5, -1.5, 31.5, 21.5) + rect(1.5, 1.5, 28.5, 18.5), dtype=float)
    legs = [((0, 0), (30, 0)), ((30, 0), (30, 20)), ((30, 20), (0, 20)), ((0, 20), (0, 0)),
            ((0, 0), (8, 0))]  # fmt: skip
    truth = []
    for (x0, y0), (x1, y1) in legs:
        th = math.atan2(y1 - y0, x1 - x0)
        if truth:  # turn on the spot, 15 deg a step
            last = truth[-1][2]
            turn = math.remainder(th - last, 2 * math.pi)
            truth += [(x0, y0, last + turn * s) for s in np.linspace(0, 1, 7)[1:]]
        n = round(math.hypot(x1 - x0, y1 - y0) / 0.25)
        truth += [(x0 + (x1 - x0) * s, y0 + (y1 - y0) * s, th) for s in np.arange(1, n + 1) / n]
    truth = np.array([(0.0, 0.0, 0.0), *truth])
    cfg = load_config("real_building_scan")
    params = dataclasses.replace(cfg.fixes, live_close_online=online, live_right_angles=False)
    aid = LiveMapPoseAid(params, cfg.fgm, flm_source=None)
    ekf = EkfSlam(truth[0], np.diag([1e-6, 1e-6, 1e-8]), (4e-6, 3e-6, 3e-5, 6e-5))
    q = np.diag([0.01**2, 0.01**2, math.radians(0.3) ** 2])
    for k, pose in enumerate(truth):
        if k:
            delta = between(truth[k - 1], pose)
            if k == 48:  # x = 12 m: the wheels slip, the odometry says 0.6 m more
                delta[0] += 0.6
            ekf.predict_relative(delta, q)
        ring = _RingView(float(k), _loop_scan(pose, walls, 8.0), 8.0, FOV)
        aid.on_ring(float(k), ring, MOUNTS, ekf)
    return aid, ekf, truth


@pytest.mark.slow
def test_an_online_loop_closure_moves_the_keyframes_the_map_and_the_filter():
    """A wheel slip in a corridor no wall measures along it: the loop's walls come back
    0.6 m off. The online closure (live_close_online) moves the keyframes back toward the
    truth, fuses the map again from them and moves the filter onto the newest keyframe,
    with an NIS the inflation keeps honest; without it the keyframes keep the slip."""
    runs = {on: _corridor_loop_run(on) for on in (True, False)}
    aid, ekf, truth = runs[True]
    off, ekf_off, _ = runs[False]
    assert aid.online_closures >= 1 and aid.online_moved_max >= 0.1
    assert off.online_closures == 0 and off.graph is None

    def key_errors(a) -> np.ndarray:
        p = np.array([f.pose for f in a._frames])
        return np.hypot(*(p[:, :2] - truth[[f.ring for f in a._frames], :2]).T)

    # the keyframes after the slip held its 0.6 m without the closure, not with it
    # (measured 0.66 and 0.16 m), and so did the filter at the end (0.65 and 0.18 m)
    assert np.mean(key_errors(off)[-60:]) > 0.3
    assert np.mean(key_errors(aid)[-60:]) < 0.5 * np.mean(key_errors(off)[-60:])
    end = [np.hypot(*(e.pose[:2] - truth[-1, :2])) for e in (ekf, ekf_off)]
    assert end[1] > 0.3 and end[0] < 0.5 * end[1]
    # every update of the filter, the closures' included, within the 99.9 % chi2 of its
    # dimension: the closure's innovation was taken into the covariance first
    nis = np.array([r.nis for _, r in ekf.robot_updates if r.accepted])
    assert nis.size > 20 and np.all(nis < 16.3)
    # the map is the keyframes' at their poses
    from fuzzyslam.fixes.live_map import LiveFgm

    again = LiveFgm(truth[0], load_config("real_building_scan").fgm)
    again.builder = type(aid.live.builder)(aid.live.map.grid, again.params)
    again.refill(aid._frames)
    np.testing.assert_array_equal(again.map.m_o, aid.live.map.m_o)


def _refill_in_turn(live, frames) -> None:
    """The refill of an online closure as it was before it became lazy (the second
    implementation): the map from nothing, every keyframe fused in time order, the grid
    grown batch by batch."""
    from fuzzyslam.fixes.live_map import REFILL_BATCH, sensor_batches, stacked_readings

    live.builder = FgmBuilder(live.builder.map.grid, live.params)
    for batch in sensor_batches(frames, REFILL_BATCH):
        poses = np.array([f.pose for f in batch], dtype=float)
        reach = np.array([live._reach(f.ranges, f.max_range, f.mounts) for f in batch])
        live._cover((poses[:, :2] - reach[:, None]).min(axis=0),
                    (poses[:, :2] + reach[:, None]).max(axis=0))  # fmt: skip
        live.builder.add_rings(poses, *stacked_readings(batch), batch[0].fov, batch[0].mounts)


def test_a_lazy_refill_is_the_full_one_bit_for_bit(monkeypatch):
    """LiveFgm.refill fuses the map again only where it is read next (LiveFgm.fresh): a
    matcher's patch, then a ring that grows the grid, then the whole map. Each read
    gives the same floats as the map fused again from all its keyframes at once (the
    grid growing during the refill and after it), and the grid is the same."""
    from fuzzyslam.fixes import live_map
    from fuzzyslam.fixes.live_map import Keyframe, LiveMatcher

    monkeypatch.setattr(live_map, "REFILL_BATCH", 4)
    monkeypatch.setattr(live_map, "REFRESH_ALL", 1.0)  # never all at once: partial reads
    cfg = load_config("real_building_scan")
    # toward -x: the grid grows on its origin's side (its cell centres' floats move)
    lines = room_lines(-90.0, -2.0, 3.0, 3.0)
    poses = np.array([[-x, 0.2 * math.sin(x / 5), 0.02 * x] for x in np.arange(0.0, 70.0, 1.5)])
    frames = [Keyframe(k, float(k), p, p, laser_ring(p, lines), RMAX, FOV, MOUNTS)
              for k, p in enumerate(poses)]  # fmt: skip
    lazy, full = (LiveFgm(poses[0], cfg.fgm) for _ in range(2))
    for live in (lazy, full):
        for f in frames[:5]:  # a map of other poses first: the refill forgets it
            live.add_ring(f.pose + np.array([0.3, -0.2, 0.1]), f.ranges, RMAX, FOV, MOUNTS)
    lazy.refill(frames)
    _refill_in_turn(full, frames)
    assert lazy.grid == full.grid and lazy.grown == full.grown >= 2

    def same(a, b, box=(slice(None), slice(None))) -> None:
        for x, y in zip((a.m_e, a.m_o, a.m_t, a.m_c), (b.m_e, b.m_o, b.m_t, b.m_c),
                        strict=True):  # fmt: skip
            np.testing.assert_array_equal(x[box], y[box])

    # a matcher's patch near the start: fused there only (the far end still stale)
    matcher = LiveMatcher(lazy, cfg.fixes)
    patch = matcher._patch(100, 100, 120)
    assert lazy._stale is not None and lazy._stale.any() and not lazy._stale[100:220, 100:220].any()
    np.testing.assert_array_equal(patch, LiveMatcher(full, cfg.fixes)._patch(100, 100, 120))
    done = ~lazy._stale
    same(lazy.builder.map, full.builder.map, done)
    # a ring past the corridor's end grows the grid: the stale cells keep their grid's
    # floats (FgmBuilder.add_rings(on=...)), and the whole map is the full refill's
    far = np.array([-88.0, 0.5, 0.2])
    for live in (lazy, full):
        live.add_ring(far, laser_ring(far, lines), RMAX, FOV, MOUNTS)
    assert lazy.grid == full.grid and lazy.grown == full.grown
    same(lazy.map, full.map)
    assert lazy._stale is None and float(full.map.m_o.sum()) > 100.0


def test_the_graph_solve_is_the_one_of_its_edges_listed_anew():
    """KeyframeGraph.solve keeps its edges as arrays between solves and builds the
    heading priors at once: the same solution, bit for bit, as the edges listed anew
    for each solve (se2.between per keyframe), before and after edges are added."""
    from fuzzyslam.fixes.live_map import HEADING_PRIOR_DEG, SOLVE_TOL, KeyframeGraph
    from fuzzyslam.fixes.pose_graph import optimise
    from fuzzyslam.se2 import between

    cfg = load_config("real_building_scan")
    rng = np.random.default_rng(3)
    g = KeyframeGraph(lambda f: None, cfg.fgm, cfg.fixes, 9.0)

    class Frame:
        def __init__(self, pose):
            self.pose = pose

    def edge(i, j):
        z = between(g.frames[i].pose, g.frames[j].pose) + rng.normal(0, [0.05, 0.05, 0.02])
        return (i, j, z, np.diag(1.0 / rng.uniform([0.02, 0.02, 0.005], [0.2, 0.2, 0.05])))

    def listed(heading_prior):
        x0 = np.array([f.pose for f in g.frames])
        edges = g.edges + g.loop_edges
        if heading_prior:
            w = np.diag([0.0, 0.0, 1.0 / math.radians(HEADING_PRIOR_DEG)])
            edges += [(0, k, between(x0[0], x0[k]), w) for k in range(1, len(x0))]
        arrays = [np.array([e[n] for e in edges]) for n in range(4)]
        return optimise(x0, *arrays, tol=SOLVE_TOL)

    for k in range(60):
        g.frames.append(Frame(np.array([0.5 * k, math.sin(k / 7), wrap_angle(0.4 * k)])))
        if k:
            g.edges.append(edge(k - 1, k))
        if k >= 20 and k % 5 == 0:
            g.loop_edges.append(edge(k - 20, k))
            for prior in (True, False):
                got, info = g.solve(prior)
                want, want_info = listed(prior)
                np.testing.assert_array_equal(got, want)
                assert {n: info[n] for n in want_info} == want_info
            g.move(got + rng.normal(0, 1e-3, got.shape))  # as an online closure does
    assert len(g.loop_edges) == 8
