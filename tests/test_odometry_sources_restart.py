"""A nav_msgs/Odometry driver that restarts mid-log at (0, 0, 0) (slam/odom_gate.py
``OdomGate.restarts``, slam/inputs.py ``LogInputs._restarted``).

The restart is built from the committed logs: from one message on, each /odom pose is
replaced by the same pose seen from the previous message's pose (a driver that
restarted right after that message and integrates on from (0, 0, 0)). No motion is
lost then, so a run of it must give the trajectory of the log as recorded to the TUM
file's precision; the old gate refused 15 messages (10 as jumps, 5 as implausible
increments) before it re-anchored, lost their motion and said nothing on stderr. A
stray pose at the origin that the stream leaves again is still refused, and so is a
burst of identical (0, 0, 0) poses (a placeholder: it does not move from the origin).
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_odometry_sources_cut import tiny_odom  # noqa: F401
from test_robust_logs import JOINTS, Tiny, cli, error_lines, keep, load_tum, rewrite, tiny  # noqa: F401

from fuzzyslam.se2 import between
from fuzzyslam.slam import odom_gate
from fuzzyslam.slam.odom_gate import OdomGate
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.reader import LogMessage, LogReader

ROOT = Path(__file__).resolve().parents[1]
MRCLAM = ROOT / "data" / "real" / "mrclam6_excerpt" / "log.mcap"
ODOM = "/odom"
TUM_ATOL = 2.5e-6  # trajectory.tum writes x, y with 6 decimals


def set_pose(msg, pose: np.ndarray) -> None:
    """Write (x, y, theta) into an Odometry's pose (z and roll, pitch zero)."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z = float(pose[0]), float(pose[1]), 0.0
    q.x, q.y, q.z, q.w = 0.0, 0.0, math.sin(0.5 * pose[2]), math.cos(0.5 * pose[2])


def restarted(at: float, drop: tuple[str, ...] = (JOINTS,)):
    """A ``rewrite`` fault: /odom from log time ``at`` on as a driver restarted at the
    origin right after the message before (each pose seen from that message's pose);
    the topics ``drop`` left out (the encoders, so that /odom is read)."""
    state: dict = {"ref": None, "prev": None}

    def fault(m: LogMessage):
        if m.topic in drop:
            return []
        if m.topic != ODOM:
            return keep(m)
        pose = M.pose_of(m.msg.pose.pose)
        if m.t >= at and state["ref"] is None:
            state["ref"] = state["prev"]
        state["prev"] = pose
        if state["ref"] is None:
            return keep(m)
        msg = copy.deepcopy(m.msg)
        set_pose(msg, between(state["ref"], pose))
        return [(m.topic, m.typename, msg, m.t)]

    return fault


@pytest.fixture(scope="module")
def runs(tiny: Tiny, tiny_odom: Path, tmp_path_factory) -> Path:  # noqa: F811
    """The tiny log read from /odom as recorded (``clean``), and with a restart at 15.25 s
    (``restart``: between two frames, so that no frame and increment share a stamp,
    whose order the reorder buffer keeps as read), run."""
    d = tmp_path_factory.mktemp("restart")
    (d / "clean").symlink_to(tiny_odom / "est")
    (d / "clean.mcap").symlink_to(tiny_odom / "odom.mcap")
    log = rewrite(tiny.log, d / "restart.mcap", restarted(15.25))
    code, out, err = cli("run", log, "-o", d / "restart", "--config", tiny.config)
    assert code == 0, err
    (d / "restart.json").write_text(out, encoding="utf-8")
    (d / "restart.err").write_text(err, encoding="utf-8")
    return d



def _run_mrclam(log, out) -> tuple[dict, str]:
    """``run`` of an MRCLAM log with its preset: (the summary, stderr)."""
    code, stdout, err = cli("run", log, "-o", out, "--config", "real_detections.yaml")
    assert code == 0, err
    return json.loads(stdout), err

def test_the_built_restart_jumps_to_the_origin_and_goes_on(runs: Path) -> None:
    """The premise: the rewritten /odom jumps metres back to near (0, 0, 0) at 15.25 s
    (one period of motion from it) and goes on from there by the recorded increments."""
    got = [
        (m.t, M.pose_of(m.msg.pose.pose)) for m in LogReader(runs / "restart.mcap").messages([ODOM])
    ]
    want = [M.pose_of(m.msg.pose.pose) for m in LogReader(runs / "clean.mcap").messages([ODOM])]
    k = next(i for i, (t, _) in enumerate(got) if t >= 15.25)
    before, first = got[k - 1][1], got[k][1]
    assert np.hypot(*before[:2]) > 2.0 and np.hypot(*first[:2]) < 0.1
    np.testing.assert_allclose(first, between(want[k - 1], want[k]), atol=1e-9)


def test_a_driver_restart_is_read_on_from_the_origin(runs: Path) -> None:
    """The restart is recognised when the poses go on from the origin: no motion lost
    (the trajectory of the log as recorded, to the TUM file's precision), one restart
    counted and no glitch, one line on stderr with its time into the log (the old gate
    lost 15 messages' motion, about 0.1 m here, and said nothing)."""
    s = json.loads((runs / "restart.json").read_text())
    assert s["warnings"].get("odometry_restarts") == 1, s["warnings"]
    for key in ("odometry_jumps", "odometry_jumps_kept", "implausible_odometry"):
        assert key not in s["warnings"], s["warnings"]
    assert "odometry_reanchored" not in s["warnings"]
    said = [ln for ln in (runs / "restart.err").read_text().splitlines() if "restarted" in ln]
    assert len(said) == 1 and "/odom's driver restarted 15.25 s into the log" in said[0], said
    got, want = (
        load_tum(runs / "restart" / "trajectory.tum"),
        load_tum(runs / "clean" / "trajectory.tum"),
    )
    assert got.shape == want.shape and len(got) > 100
    np.testing.assert_allclose(got[:, :3], want[:, :3], rtol=0, atol=TUM_ATOL)


@pytest.mark.slow  # end to end, about 1 s: the fast tier stays under a minute
def test_a_restart_in_a_real_log_is_read_on_from_the_origin(tmp_path: Path) -> None:
    """The same on the MRCLAM excerpt (a real robot's /odom at 16 Hz, landmark
    detections): the restart 75 s in is said, in seconds into the log as the filter_health
    line (it printed the Unix stamp, t = 1248444266.644 s), and the run follows the
    recorded log."""
    reader = LogReader(MRCLAM)
    at = reader.start + 75.0
    first = next(m.t for m in reader.messages([ODOM]) if m.t >= at) - reader.start
    logs = {"clean": MRCLAM, "restart": rewrite(MRCLAM, tmp_path / "r.mcap", restarted(at, ()))}
    out = {name: _run_mrclam(log, tmp_path / name) for name, log in logs.items()}
    s, err = out["restart"]
    assert s["warnings"].get("odometry_restarts") == 1 and "odometry_jumps" not in s["warnings"]
    said = [ln for ln in error_lines(err) if "driver restarted" in ln]
    assert len(said) == 1 and f"driver restarted {first:.2f} s into the log (" in said[0], err
    got, want = (
        load_tum(tmp_path / "restart" / "trajectory.tum"),
        load_tum(tmp_path / "clean" / "trajectory.tum"),
    )
    assert got.shape == want.shape
    np.testing.assert_allclose(got[:, :3], want[:, :3], rtol=0, atol=TUM_ATOL)


# -- the gate on its own ------------------------------------------------------------------


def line(n: int, speed: float = 1.0, dt: float = 0.05, start=(0.0, 0.0, 0.0)):
    """(times (n,), poses (n, 3)) of a robot driving straight along its heading."""
    t = np.arange(n) * dt
    x0, y0, th = start
    poses = np.column_stack(
        [x0 + speed * t * math.cos(th), y0 + speed * t * math.sin(th), np.full(n, th)]
    )
    return t, poses


def statuses(gate: OdomGate, t: np.ndarray, poses: np.ndarray) -> list[str]:
    return [gate.step(float(ti), p) for ti, p in zip(t, poses, strict=True)]


def test_the_gate_confirms_a_restart_after_the_poses_that_go_on() -> None:
    """A stream that drops from (5, 3) to the origin and drives on from there: the pose
    at the origin and the next are held, the one after confirms it (``restart``) with
    the held poses; then ``ok`` from the new origin. Without ``restarts`` the old rule:
    ten refusals, then ``reset``."""
    t1, p1 = line(20, start=(4.0, 3.0, 0.3))
    t2, p2 = line(20)
    t = np.concatenate([t1, t1[-1] + 0.05 + t2])
    p = np.vstack([p1, p2 + np.array([0.05, 0.0, 0.0])])  # one period of motion since restart
    gate = OdomGate(restarts=True)
    got = statuses(gate, t, p)
    assert got[:20] == ["first"] + ["ok"] * 19
    assert got[20 : 21 + odom_gate.RESTART_CONFIRM] == ["jump"] * odom_gate.RESTART_CONFIRM + [
        "restart"
    ]
    assert set(got[21 + odom_gate.RESTART_CONFIRM :]) == {"ok"}
    held = gate.restarted
    assert len(held) == odom_gate.RESTART_CONFIRM + 1 and held[0][0] == pytest.approx(t[20])
    np.testing.assert_array_equal(held[0][1], p[20])
    old = statuses(OdomGate(), t, p)
    assert old[20:30] == ["jump"] * 9 + ["reset"] and "restart" not in old


@pytest.mark.parametrize("stray", [1, 2])
def test_stray_poses_at_the_origin_are_refused_as_before(stray: int) -> None:
    """One or two poses of zeros (a converter's placeholder) in a stream that then goes
    on where it was: refused (``jump``), no restart, as without ``restarts``."""
    t, p = line(40, start=(4.0, 3.0, 0.3))
    p = p.copy()
    p[20 : 20 + stray] = 0.0
    got = statuses(OdomGate(restarts=True), t, p)
    assert got == statuses(OdomGate(), t, p)
    assert got[20 : 20 + stray] == ["jump"] * stray and set(got[20 + stray :]) == {"ok"}


def zeroed(at: float, n: int):
    """A ``rewrite`` fault: the ``n`` /odom poses from log time ``at`` on set to (0, 0, 0)
    (a converter's placeholder burst; the reviewer's construction)."""
    left = {"n": n}

    def fault(m: LogMessage):
        if m.topic != ODOM or m.t < at or left["n"] <= 0:
            return keep(m)
        left["n"] -= 1
        msg = copy.deepcopy(m.msg)
        set_pose(msg, np.zeros(3))
        return [(m.topic, m.typename, msg, m.t)]

    return fault


@pytest.mark.parametrize("burst", [3, 4, 8])
def test_a_burst_of_zero_poses_is_refused_not_a_restart(burst: int) -> None:
    """``burst`` identical poses at the origin in a moving stream: each passes "from the
    origin" and each goes on "smoothly" from the one before, but none moves: refused
    (``jump``) and the stream read on where it was, as without ``restarts`` (the
    unchecked rule confirmed a restart on the third zero and lost the position)."""
    t, p = line(40, start=(4.0, 3.0, 0.3))
    p = p.copy()
    p[20 : 20 + burst] = 0.0
    gate = OdomGate(restarts=True)
    got = statuses(gate, t, p)
    assert got == statuses(OdomGate(), t, p)
    assert got[20 : 20 + burst] == ["jump"] * burst and set(got[20 + burst :]) == {"ok"}
    np.testing.assert_array_equal(gate.pose, p[-1])


def test_a_restart_while_standing_still_is_the_old_reset() -> None:
    """A driver that restarts while the robot stands (poses at the origin, unmoving):
    no restart is confirmed (nothing tells it from a placeholder burst); the old rule's
    ``reset`` after ten refusals reads the stream on from there (nothing moved meanwhile),
    and the drive that follows is ``ok``."""
    t1, p1 = line(20, start=(4.0, 3.0, 0.3))
    t2, p2 = line(20)
    t = np.concatenate([t1, t1[-1] + 0.05 + np.arange(15) * 0.05, t1[-1] + 0.8 + t2])
    p = np.vstack([p1, np.zeros((15, 3)), p2])
    got = statuses(OdomGate(restarts=True), t, p)
    assert "restart" not in got
    assert got[20:30] == ["jump"] * 9 + ["reset"] and set(got[30:]) == {"ok"}


def test_a_slow_restart_is_confirmed_once_it_has_moved() -> None:
    """A restart followed by a slow drive (6 cm/s, 20 Hz: 3 mm a pose): held until the
    poses have moved over ``RESTART_MOVED_M`` from the candidate, then confirmed with all
    the held poses (none lost)."""
    t1, p1 = line(20, start=(4.0, 3.0, 0.3))
    t2, p2 = line(20, speed=0.06)
    t = np.concatenate([t1, t1[-1] + 0.05 + t2])
    gate = OdomGate(restarts=True)
    got = statuses(gate, t, np.vstack([p1, p2]))
    k = got.index("restart")
    need = math.floor(odom_gate.RESTART_MOVED_M / 0.003) + 1  # poses after the candidate
    assert need > odom_gate.RESTART_CONFIRM
    assert k == 20 + need and got[20:k] == ["jump"] * need and set(got[k + 1 :]) == {"ok"}
    assert len(gate.restarted) == need + 1 and gate.restarted[0][0] == pytest.approx(t[20])


@pytest.mark.slow
def test_a_burst_of_zeros_in_a_real_log_is_refused(tmp_path: Path) -> None:
    """The reviewer's case: four /odom poses of the MRCLAM excerpt halfway in set to
    (0, 0, 0). The four are refused as jumps and nothing else is said or counted: no
    restart (the unchecked rule: "driver restarted", 9 jumps, a re-anchoring), and the
    dead reckoning is that of the clean log (the unchecked rule moved its end 0.54 m)."""
    reader = LogReader(MRCLAM)
    odo = [m.t for m in reader.messages([ODOM])]
    logs = {
        "clean": MRCLAM,
        "zeros": rewrite(MRCLAM, tmp_path / "z.mcap", zeroed(odo[len(odo) // 2], 4)),
    }
    out = {name: _run_mrclam(log, tmp_path / name) for name, log in logs.items()}
    s, err = out["zeros"]
    want = dict(out["clean"][0]["warnings"], odometry_jumps=4)
    assert s["warnings"] == want, s["warnings"]
    assert "restarted" not in err
    got, clean = (
        load_tum(tmp_path / "zeros" / "odometry.tum"),
        load_tum(tmp_path / "clean" / "odometry.tum"),
    )
    assert np.hypot(*(got[-1, 1:3] - clean[-1, 1:3])) < 0.01


def test_a_jump_near_the_origin_that_does_not_go_on_is_no_restart() -> None:
    """Poses at the origin that do not drive on from it (each a metre from the last):
    never a restart; the old rule's ``reset`` after ten refusals stands."""
    t, p = line(40, start=(4.0, 3.0, 0.3))
    p = p.copy()
    p[20:] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]] * 10
    gate = OdomGate(restarts=True)
    got = statuses(gate, t, p)
    assert "restart" not in got and got[29] == "reset"
