"""`fuzzyslam run` end to end on a simulated quick.yaml log, and on small hand-made logs."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from conftest import shared_dir
from scipy.optimize import linear_sum_assignment

from fuzzyslam import se2
from fuzzyslam.cli import _register, cli
from fuzzyslam.config import load_config
from fuzzyslam.streams import messages as M
from fuzzyslam.streams.logmeta import read_world
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.tum import read_tum
from fuzzyslam.streams.writer import LogWriter

_register()


def invoke(args):
    return CliRunner().invoke(cli, args, catch_exceptions=False)


@pytest.fixture(scope="session")
def quick_log(tmp_path_factory) -> Path:
    """One simulated quick.yaml recording (2 laps, ~250 s) per test run (conftest.shared_dir)."""

    def build(root: Path) -> None:
        res = invoke(["simulate", "quick", "-o", str(root / "quick.mcap"), "--seed", "3"])
        assert res.exit_code == 0, res.output

    return shared_dir(tmp_path_factory, "e2e-quick-log", build) / "quick.mcap"


@pytest.fixture(scope="session")
def quick_run(quick_log, tmp_path_factory) -> tuple[Path, dict]:
    def build(root: Path) -> None:
        args = ["run", str(quick_log), "-o", str(root / "est"), "--config", "quick"]
        res = CliRunner().invoke(cli, args)
        assert res.exit_code == 0, res.output
        (root / "stdout.json").write_text(res.stdout)

    root = shared_dir(tmp_path_factory, "e2e-quick-run", build)
    return root / "est", json.loads((root / "stdout.json").read_text())


def truth(log: Path) -> np.ndarray:
    rows = [
        (m.t, *M.pose_of(m.msg.pose.pose)) for m in LogReader(log).messages(["/ground_truth/odom"])
    ]
    return np.array(rows)


@pytest.mark.slow
def test_quick_accuracy_and_no_duplicate(quick_log, quick_run):
    out, summary = quick_run
    t, est = read_tum(out / "trajectory.tum")
    gt = truth(quick_log)
    gx = np.interp(t, gt[:, 0], gt[:, 1])
    gy = np.interp(t, gt[:, 0], gt[:, 2])
    pos_err = np.hypot(est[:, 0] - gx, est[:, 1] - gy)
    assert pos_err.mean() < 0.05
    world = read_world(LogReader(quick_log))
    lamps = yaml.safe_load((out / "landmarks.yaml").read_text())["landmarks"]
    est_l = np.array([[d["x"], d["y"]] for d in lamps])
    true_l = world.lamp_array
    assert len(est_l) == len(true_l), "a duplicate or a missing lamp"
    d = np.hypot(*(est_l[:, None, :] - true_l[None, :, :]).transpose(2, 0, 1))
    ri, ci = linear_sum_assignment(d)
    assert d[ri, ci].mean() < 0.05 and d[ri, ci].max() < 0.15
    assert summary["lamps"] == len(true_l) and summary["counts"]["lamps_created"] == len(true_l)
    # the filter is consistent on average: lamp NIS near its 2 dof (conservative allowed)
    assert 0.5 < summary["mean_nis_lamp"] < 3.0


@pytest.mark.slow
def test_output_files_follow_the_contract(quick_run):
    out, summary = quick_run
    for name in (
        "trajectory.tum",
        "odometry.tum",
        "covariance.csv",
        "landmarks.yaml",
        "updates.csv",
        "estimates.mcap",
        "summary.json",
    ):
        assert (out / name).is_file(), name
    t, _ = read_tum(out / "trajectory.tum")
    cov = (out / "covariance.csv").read_text().splitlines()
    assert cov[0] == "t,pxx,pxy,pxt,pyy,pyt,ptt" and len(cov) - 1 == len(t)
    c = np.loadtxt(out / "covariance.csv", delimiter=",", skiprows=1)
    assert np.allclose(c[:, 0], t, atol=1e-6)
    upd = (out / "updates.csv").read_text().splitlines()
    assert upd[0] == "t,kind,id,dof,nis,accepted,v0,v1,v2"
    assert len(upd) - 1 >= summary["counts"]["associated"]
    _, odo = read_tum(out / "odometry.tum")
    assert np.allclose(odo[0], summary["start_pose"])
    assert json.loads((out / "summary.json").read_text()) == summary
    topics = LogReader(out / "estimates.mcap").topics
    assert topics["/slam/pose"] == M.POSE_COV_STAMPED
    assert topics["/slam/landmarks"] == M.MARKER_ARRAY


class CheckingAid:
    """A test aid: at every ring P must be symmetric positive definite."""

    def __init__(self, start_time: float) -> None:
        self.start_time = start_time
        self.calls = 0
        self.first_t = None
        self.min_eig = np.inf

    def on_ring(self, t, ring, mounts, ekf) -> None:
        assert t >= self.start_time and mounts.shape == (16, 3) and ring.ranges.shape == (16,)
        p = ekf.P
        assert np.array_equal(p, p.T)
        self.min_eig = min(self.min_eig, float(np.linalg.eigvalsh(p)[0]))
        self.first_t = t if self.first_t is None else self.first_t
        self.calls += 1

    def summary(self) -> dict:
        return {"calls": self.calls}

    def write(self, outdir: Path) -> None:
        (outdir / "aid.txt").write_text(str(self.calls))


@pytest.mark.slow
def test_covariance_spd_through_a_whole_run_and_aid_protocol(quick_log, tmp_path):
    from fuzzyslam.slam.stage import run_stage

    aid = CheckingAid(start_time=10.0)
    summary = run_stage(quick_log, tmp_path / "o", load_config("quick"), [aid])
    assert aid.calls > 500 and aid.first_t >= 10.0 and aid.min_eig > 0.0
    assert (tmp_path / "o" / "aid.txt").read_text() == str(aid.calls)
    assert summary["aids"]["CheckingAid"] == {"calls": aid.calls}


# -- small hand-made logs (a "real robot" log: /odom and PoseArray detections) -------------


LAMPS = np.array([[1.0, 0.5], [2.5, -0.6], [4.0, 0.4], [5.5, -0.5]])


def write_robot_log(path: Path, nan_at=None, back_at=None, encoding=None) -> None:
    """Straight drive along x at 0.3 m/s for 20 s; exact /odom; lamps seen within 2 m."""
    with LogWriter(path) as w:
        for k in range(401):
            t = 0.05 * k
            pose = np.array([0.3 * t, 0.0, 0.0])
            if nan_at is not None and k == nan_at:
                pose = np.array([np.nan, 0.0, 0.0])
            w.write("/odom", M.ODOMETRY, M.odometry(t, "odom", "base_link", pose), t)
            if k % 4 == 0:
                z = se2.inverse_transform_points(pose, LAMPS)
                z = z[np.hypot(z[:, 0], z[:, 1]) < 2.0]
                stamp = t - 1.0 if back_at is not None and k == back_at else t
                if encoding is None:
                    w.write(
                        "/ceiling_camera/detections",
                        M.POSE_ARRAY,
                        M.pose_array(stamp, "base_link", z),
                        t,
                    )
                else:
                    img = M.image_mono8(t, "ceiling_camera", np.zeros((12, 16), np.uint8))
                    img.encoding = encoding
                    w.write("/ceiling_camera/image_raw", M.IMAGE, img, t)
                    info = M.camera_info(t, "ceiling_camera", 16, 12, 10.0, 7.5, 5.5)
                    w.write("/ceiling_camera/camera_info", M.CAMERA_INFO, info, t)


def test_odom_and_pose_array_log_maps_lamps(tmp_path):
    log = tmp_path / "robot.mcap"
    write_robot_log(log)
    res = invoke(["run", str(log), "-o", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    s = json.loads(res.stdout)
    assert s["odometry_source"].startswith("odom") and s["lamp_source"].startswith("detections")
    lamps = yaml.safe_load((tmp_path / "o" / "landmarks.yaml").read_text())["landmarks"]
    est = np.array([[d["x"], d["y"]] for d in lamps])
    assert len(est) == len(LAMPS)
    d = np.hypot(*(est[:, None, :] - LAMPS[None, :, :]).transpose(2, 0, 1))
    assert np.all(d.min(axis=0) < 0.02)


def test_nan_odometry_and_out_of_order_are_counted(tmp_path):
    log = tmp_path / "glitch.mcap"
    write_robot_log(log, nan_at=100, back_at=200)
    res = invoke(["run", str(log), "-o", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    s = json.loads(res.stdout)
    assert s["warnings"]["nan_odometry"] == 1 and s["warnings"]["out_of_order"] == 1
    assert s["lamps"] == len(LAMPS)


def run_main(args) -> tuple[int, str]:
    import contextlib
    import io

    from fuzzyslam.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), pytest.raises(SystemExit) as ex:
        main(args)
    return int(ex.value.code), err.getvalue()


def test_not_mcap_is_one_line_exit_3_nothing_left(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_text("not an mcap file")
    code, err = run_main(["run", str(bad), "-o", str(tmp_path / "out")])
    assert code == 3 and "not an MCAP file" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]


def test_log_without_lamps_is_dead_reckoning_with_a_note(tmp_path):
    """No camera and no detections (issue 13): the filter runs on odometry alone, from the
    first odometry pose, and one line on stderr names the lamp topics and config keys."""
    log = tmp_path / "odom_only.mcap"
    poses = np.array(
        [[1.0 + 0.1 * k * np.cos(0.5), 2.0 + 0.1 * k * np.sin(0.5), 0.5] for k in range(5)]
    )
    with LogWriter(log) as w:
        for k in range(5):
            w.write(
                "/odom", M.ODOMETRY, M.odometry(k * 0.1, "odom", "base_link", poses[k]), k * 0.1
            )
    code, err = run_main(["run", str(log), "-o", str(tmp_path / "out")])
    assert code == 0
    note = [ln for ln in err.splitlines() if "note" in ln]
    assert len(note) == 1 and "dead reckoning" in note[0]
    assert "/ceiling_camera/image_raw" in note[0] and "topics.detections" in note[0]
    from fuzzyslam.streams.tum import read_tum

    _t, est = read_tum(tmp_path / "out" / "odometry.tum")
    assert np.allclose(est[0], poses[0])  # the first odometry pose (no scenario)
    assert np.allclose(est[-1], poses[-1])  # straight motion: dead reckoning is exact


def test_wrong_image_encoding_is_a_clear_error(tmp_path):
    log = tmp_path / "rgb.mcap"
    write_robot_log(log, encoding="rgb8")
    code, err = run_main(["run", str(log), "-o", str(tmp_path / "out")])
    assert code == 3 and "rgb8" in err and "mono8" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_reader_equals_mcap_and_rosbags(quick_log):
    """LogReader's indexed backend and fast decoders against a second implementation,
    the mcap library's reader (log-time order) and rosbags' deserializer: the same
    messages in the same order with the same fields."""
    from mcap.reader import make_reader

    from fuzzyslam.streams.typestore import deserialize

    topics = ["/joint_states", "/ceiling_camera/image_raw", "/sonar/s03", "/odom"]
    a = list(LogReader(quick_log).messages(topics))
    with open(quick_log, "rb") as f:
        b = [
            (ch.topic, m.log_time, deserialize(m.data, sc.name))
            for sc, ch, m in make_reader(f).iter_messages(topics=topics, log_time_order=True)
        ]
    assert [(m.topic, m.t_ns) for m in a] == [(t, ns) for t, ns, _ in b] and len(a) > 1000
    assert {m.topic for m in a} == set(topics)
    for x, (_, _, y) in zip(a, b, strict=True):
        assert x.msg.header.stamp.sec == y.header.stamp.sec
        assert x.msg.header.stamp.nanosec == y.header.stamp.nanosec
        assert x.msg.header.frame_id == y.header.frame_id
        if x.topic == "/joint_states":
            assert x.msg.name == y.name and np.array_equal(x.msg.position, y.position)
        elif x.topic == "/odom":
            assert np.array_equal(x.msg.pose.covariance, y.pose.covariance)
            assert x.msg.pose.pose.orientation.w == y.pose.pose.orientation.w
        elif x.topic == "/sonar/s03":
            assert (x.msg.range, x.msg.max_range) == (y.range, y.max_range)
        else:
            for f in ("height", "width", "encoding", "is_bigendian", "step"):
                assert getattr(x.msg, f) == getattr(y, f)
            assert np.array_equal(x.msg.data, y.data)


# -- streamed outputs (issue 7) ---------------------------------------------------------------


def _mcap_messages(path: Path) -> dict:
    """Per topic: (log time, publish time, sequence, CDR payload) of every message."""
    from mcap.reader import make_reader

    out: dict = {}
    with open(path, "rb") as f:
        for _schema, channel, msg in make_reader(f).iter_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append(
                (msg.log_time, msg.publish_time, msg.sequence, bytes(msg.data))
            )
    return out


@pytest.mark.slow
def test_streamed_outputs_do_not_depend_on_blocks(quick_log, quick_run, tmp_path, monkeypatch):
    """`run` streams its rows to files in blocks. With tiny blocks (7 rows, 5 odometry
    increments, so that many block boundaries are crossed) the files are the same bytes as
    with the default blocks (the shared ``quick_run``: the same log and config through the
    CLI; estimates.mcap: the same messages, payloads, times, sequence numbers); and they
    hold the rows of the in-memory run (MemorySink): the trajectory, and the dead
    reckoning of ``robot.integrate`` on the whole increments at once."""
    from fuzzyslam.slam.inputs import open_inputs
    from fuzzyslam.slam.outputs import StreamingOutputs
    from fuzzyslam.slam.runner import SlamRunner
    from fuzzyslam.slam.stage import calibration_model, run_stage
    from fuzzyslam.streams.tum import format_tum

    cfg = load_config("quick")
    assert StreamingOutputs.rows_block != 7 and StreamingOutputs.odometry_block != 5
    monkeypatch.setattr(StreamingOutputs, "rows_block", 7)
    monkeypatch.setattr(StreamingOutputs, "odometry_block", 5)
    summary = run_stage(quick_log, tmp_path / "streamed", cfg)

    default_blocks, whole = quick_run
    a, b = tmp_path / "streamed", default_blocks
    for name in ("trajectory.tum", "odometry.tum", "covariance.csv", "updates.csv"):
        same = (a / name).read_bytes() == (b / name).read_bytes()  # no diff of megabytes
        assert same, name
    assert (a / "landmarks.yaml").read_bytes() == (b / "landmarks.yaml").read_bytes()
    ma, mb = _mcap_messages(a / "estimates.mcap"), _mcap_messages(b / "estimates.mcap")
    assert ma == mb
    for key in ("trajectory_rows", "final_pose", "mean_nis_lamp", "counts"):
        assert summary[key] == whole[key]

    inputs = open_inputs(quick_log, cfg)
    runner = SlamRunner(cfg.slam, inputs.start_pose, [], inputs.mounts, cfg.slam.landmarks_period,
                        calibration=calibration_model(inputs, cfg, None))  # fmt: skip
    res = runner.run(inputs.events(), t0=inputs.start)  # every row in memory
    assert (a / "trajectory.tum").read_text() == format_tum(res.t, res.poses)
    assert (a / "odometry.tum").read_text() == format_tum(res.odo_t, res.odo_poses)
    assert len(ma["/slam/pose"]) == len(ma["/tf"]) == len(res.t) > 1000
    assert len(ma["/slam/landmarks"]) == len(res.snapshots) > 10
    # the streamed file is in log-time order (poses and lamp snapshots interleaved)
    times = [m.t for m in LogReader(a / "estimates.mcap").messages()]
    assert times == sorted(times)
    assert summary["trajectory_rows"] == len(res.t)
    assert summary["final_pose"] == [float(v) for v in res.poses[-1]]
    assert summary["mean_nis_lamp"] == pytest.approx(res.mean_nis("lamp"), rel=1e-12)


@pytest.mark.slow
def test_interrupted_mid_run_leaves_nothing(quick_log, tmp_path, monkeypatch):
    """Ctrl-C in the middle of the filter, after rows were streamed into the staging
    directory: no output directory, no temporary file or directory left."""
    from fuzzyslam.slam import runner as runner_mod
    from fuzzyslam.slam.stage import run_stage

    real = runner_mod.SlamRunner.frame
    seen = []

    def frame(self, ev):
        seen.append(ev.t)
        if len(seen) == 600:  # rows are being written to the staging directory
            staged = [p for p in tmp_path.iterdir() if p.name.endswith(".part")]
            assert len(staged) == 1 and (staged[0] / "trajectory.tum").is_file()
            raise KeyboardInterrupt
        return real(self, ev)

    monkeypatch.setattr(runner_mod.SlamRunner, "frame", frame)
    with pytest.raises(KeyboardInterrupt):
        run_stage(quick_log, tmp_path / "est", load_config("quick"))
    assert len(seen) == 600 and list(tmp_path.iterdir()) == []
