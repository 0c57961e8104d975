"""`fuzzyslam evaluate` end to end on a hand-made log and run directory with known answers."""

from __future__ import annotations

import contextlib
import io
import itertools
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml

from fuzzyslam.cli import main
from fuzzyslam.evaluation.evaluate import detect_kind, read_estimate, read_truth
from fuzzyslam.streams.logmeta import SCENARIO_KEY, WORLD_KEY
from fuzzyslam.streams.messages import MARKER_ARRAY, ODOMETRY, marker, marker_array, odometry
from fuzzyslam.streams.tum import write_tum
from fuzzyslam.streams.writer import LogWriter

pytestmark = pytest.mark.slow  # end to end: simulate, run and evaluate per fixture

OFFSET = np.array([0.03, -0.04])  # the estimate's constant position error (m)
SIGMA_XY, SIGMA_TH = 0.05, 0.02  # its stated standard deviations
LAMPS = [[1.0, 0.0], [3.0, 0.0], [4.0, 1.5], [2.0, 3.0], [0.0, 1.5]]
LAMP_SHIFT = np.array([0.06, 0.08])  # lamp 2 estimated 10 cm off


def _truth_path(n_per_run: int = 200) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """Two laps of a 4 x 3 m rectangle, one each way, at 20 Hz."""
    corners = np.array([[0, 0], [4, 0], [4, 3], [0, 3], [0, 0]], dtype=float)
    seg = np.linspace(0, 1, n_per_run // 4, endpoint=False)
    lap = np.vstack([a + np.outer(seg, b - a) for a, b in itertools.pairwise(corners)])
    xy = np.vstack([lap, lap[::-1]])
    d = np.gradient(xy, axis=0)
    th = np.arctan2(d[:, 1], d[:, 0])
    t = np.arange(xy.shape[0]) * 0.05
    events = [
        {"t": 0.0, "kind": "run_start", "run": 1, "direction": 1},
        {"t": float(t[n_per_run - 1]), "kind": "run_end", "run": 1},
        {"t": float(t[n_per_run]), "kind": "run_start", "run": 2, "direction": -1},
        {"t": float(t[-1]), "kind": "run_end", "run": 2},
        {"t": float(t[n_per_run]), "kind": "lamp_failure", "lamps": [1, 3]},
    ]
    return t, np.column_stack([xy, th]), events


@pytest.fixture(scope="session")
def case(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("evalcase")
    t, truth, events = _truth_path()
    world = {
        "walls": [[-1, -1, 5, -1], [5, -1, 5, 4], [5, 4, -1, 4], [-1, 4, -1, -1]],
        "lamps": LAMPS,
        "lamp_radius": 0.1,
        "corridors": [],
        "centerline": [[0, 0], [4, 0], [4, 3], [0, 3]],
        "ceiling_height": 2.5,
    }
    scenario = {
        "name": "evaltest",
        "seed": 0,
        "start_pose": truth[0].tolist(),
        "duration": float(t[-1]),
        "events": events,
        "config": {"fgm": {"freeze_run": 1}},
    }
    log = root / "sim.mcap"
    with LogWriter(log) as w:
        w.json_metadata(WORLD_KEY, world)
        w.json_metadata(SCENARIO_KEY, scenario)
        for ti, p in zip(t, truth, strict=True):
            w.write("/ground_truth/odom", ODOMETRY, odometry(ti, "map", "base_link", p), ti)
    nogt = root / "nogt.mcap"
    with LogWriter(nogt) as w:
        w.json_metadata(WORLD_KEY, world)
        w.write("/odom", ODOMETRY, odometry(0.0, "odom", "base_link", truth[0]), 0.0)
    # the estimate: at 10 Hz, half a sample period off the truth's clock
    te = t[::2][:-1] + 0.025
    idx = np.arange(te.size) * 2
    est = 0.5 * (truth[idx] + truth[idx + 1])
    est[:, 2] = np.arctan2(
        np.sin(truth[idx, 2]) + np.sin(truth[idx + 1, 2]),
        np.cos(truth[idx, 2]) + np.cos(truth[idx + 1, 2]),
    )
    est[:, :2] += OFFSET
    run = root / "run"
    run.mkdir()
    write_tum(run / "trajectory.tum", te, est)
    odo = est.copy()
    odo[:, 0] += np.linspace(0, 1.0, te.size)
    write_tum(run / "odometry.tum", te, odo)
    cov = [SIGMA_XY**2, 0.0, 0.0, SIGMA_XY**2, 0.0, SIGMA_TH**2]
    rows = ["t,pxx,pxy,pxt,pyy,pyt,ptt"] + [",".join(map(str, [ti, *cov])) for ti in te]
    (run / "covariance.csv").write_text("\n".join(rows) + "\n")
    lm = np.array(LAMPS)
    lm[2] += LAMP_SHIFT
    lms = [{"id": i, "x": float(x), "y": float(y)} for i, (x, y) in enumerate(lm)]
    lms.append({"id": 9, "x": LAMPS[0][0] + 0.2, "y": LAMPS[0][1]})  # a duplicate of lamp 0
    lms = [d for d in lms if d["id"] != 4]  # lamp 4 never mapped
    (run / "landmarks.yaml").write_text(yaml.safe_dump({"frame": "map", "landmarks": lms}))
    # map snapshots: at 9 s (in run 1) lamp 2 is 20 cm off, at 15 s as in landmarks.yaml
    early = lm.copy()
    early[2] = np.add(LAMPS[2], [0.2, 0.0])
    with LogWriter(run / "estimates.mcap") as w:
        for ts, xy in ((9.0, early), (15.0, np.array([[d["x"], d["y"]] for d in lms]))):
            mks = [marker(ts, "map", "lamps", i, 2, (x, y, 0.0)) for i, (x, y) in enumerate(xy)]
            mks += [marker(ts, "map", "lamp_ids", i, 9, (9.0, 9.0, 0.0)) for i in range(len(xy))]
            w.write("/slam/landmarks", MARKER_ARRAY, marker_array(mks), ts)
    rng = np.random.default_rng(0)
    nis = rng.chisquare(2, size=400)
    rows = ["t,kind,id,dof,nis,accepted,v0,v1,v2"] + [
        f"{te[i % te.size]},lamp,{i % 5},2,{v},1,0.1,0.1," for i, v in enumerate(nis)
    ]
    (run / "updates.csv").write_text("\n".join(rows) + "\n")
    fix_t = te[120:170]
    th_true = np.interp(fix_t, t, np.unwrap(truth[:, 2]))
    fix_err = np.deg2rad(rng.normal(1.0, 0.5, size=fix_t.size))
    rows = ["t,corridor,measured,predicted,accepted,reason,strength"] + [
        f"{a},0,{b},{b},1,ok,1.0" for a, b in zip(fix_t, th_true + fix_err, strict=True)
    ]
    (run / "heading_fixes.csv").write_text("\n".join(rows) + "\n")
    late = root / "late.tum"
    write_tum(late, te + 1000.0, est)
    junk = root / "junk.bin"
    junk.write_bytes(bytes(range(256)) * 4)
    fgm = root / "fgm"
    fgm.mkdir()
    ny, nx = 60, 70
    m_o = np.zeros((ny, nx), np.float32)
    m_o[[5, -6], 5:-5] = 0.9
    np.savez(
        fgm / "fgm.npz",
        m_e=1 - m_o,
        m_o=m_o,
        m_t=np.zeros_like(m_o),
        m_c=np.zeros_like(m_o),
        origin=np.array([-1.0, -1.5]),
        resolution=0.1,
        shape=np.array([ny, nx]),
        frozen=True,
        freeze_time=10.0,
    )
    truth_tum = root / "truth.tum"
    write_tum(truth_tum, t, truth)
    return {
        "log": log,
        "fgm": fgm,
        "nogt": nogt,
        "run": run,
        "late": late,
        "junk": junk,
        "truth_tum": truth_tum,
        "root": root,
        "fix_err": fix_err,
    }


@dataclass
class CliResult:
    returncode: int
    stdout: str
    stderr: str


def _cli(*args: object) -> CliResult:
    """Run the CLI entry point in-process (as the console script does) and capture it."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            main([str(a) for a in args])
            code = 0
        except SystemExit as exc:
            code = int(exc.code or 0)
    return CliResult(code, out.getvalue(), err.getvalue())


@pytest.fixture(scope="session")
def report(case: dict) -> tuple[Path, dict, dict]:
    out = case["root"] / "report"
    r = _cli("evaluate", case["log"], case["run"], "-o", out, "--label", "test")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    return out, summary, json.loads((out / "metrics.json").read_text())


def test_kinds_detected_by_content(case: dict) -> None:
    assert detect_kind(case["log"]) == "mcap"
    assert detect_kind(case["run"]) == "rundir"
    assert detect_kind(case["late"]) == "tum"
    from fuzzyslam.errors import InputError

    with pytest.raises(InputError, match="unknown file kind"):
        detect_kind(case["junk"])


def test_readers(case: dict) -> None:
    tr = read_truth(case["log"])
    assert tr.world is not None and tr.scenario is not None and tr.freeze_run == 1
    est = read_estimate(case["run"])
    assert est.cov is not None and est.cov.shape == (est.t.size, 3, 3)
    assert est.landmarks is not None and est.landmarks.shape == (5, 2)


def test_report_known_answers(case: dict, report: tuple) -> None:
    _, summary, m = report
    off = float(np.hypot(*OFFSET))
    ov = m["phases"]["overall"]
    # truth interpolated at the estimate's times: the only error is the constant offset
    assert ov["position_m"]["mean"] == pytest.approx(off, abs=1e-5)
    assert ov["x_m"]["bias"] == pytest.approx(OFFSET[0], abs=1e-5)
    assert ov["ape_m"]["raw"]["rmse"] == pytest.approx(off, abs=1e-5)
    assert ov["ape_m"]["aligned"]["rmse"] < 1e-4
    # a simulated log's truth is exact: not passed through the stray-line test
    assert "truth_lines_dropped" not in m and "truth_lines_dropped" not in summary
    assert abs(ov["heading_deg"]["mean"]) < 1e-3
    assert ov["nees"]["mean"] == pytest.approx(off**2 / SIGMA_XY**2, rel=1e-3)
    assert set(m["phases"]) == {"overall", "run1", "run2", "A", "after"}
    assert m["phases"]["A"]["samples"] + m["phases"]["after"]["samples"] == ov["samples"]
    lm = m["lamps"]
    assert (lm["duplicates"], lm["missed"], lm["matched"]) == (1, 1, 4)
    assert lm["per_lamp_error_m"][2] == pytest.approx(0.1, abs=1e-9)
    assert lm["per_lamp_error_m"][4] is None
    nis = ov["nis"]["lamp_dof2"]
    assert nis["n"] == 400 and nis["band_lo"] < 2.0 < nis["band_hi"]
    fx = ov["heading_fix"]["error_deg"]
    fix_err = np.degrees(case["fix_err"])
    assert fx["n"] == fix_err.size
    assert fx["bias"] == pytest.approx(fix_err.mean(), abs=1e-3)
    assert fx["std"] == pytest.approx(fix_err.std(), abs=1e-3)
    assert ov["heading_fix"]["reasons"] == {"ok": fix_err.size}
    assert m["odometry"]["position_m"]["max"] > 0.9
    assert summary["lamps_duplicated"] == 1
    assert summary["position_mean_m"] == pytest.approx(off, abs=1e-5)


def test_report_files(report: tuple) -> None:
    out, summary, _ = report
    md = (out / "report.md").read_text()
    for png in ("fig1_paths.png", "fig3_errors.png", "fig4_lamps.png", "consistency.png"):
        assert (out / png).stat().st_size > 10_000
        assert f"({png})" in md
        assert png in summary["files"]
    assert "| A |" in md and "| after |" in md
    assert not [p for p in out.parent.iterdir() if p.name.endswith(".part")]


def test_lamp_snapshots_by_run(report: tuple) -> None:
    m = report[2]["lamps_by_run"]
    assert m["run1"]["t"] == 9.0 and m["run2"]["t"] == 15.0
    assert m["run1"]["per_lamp_error_m"][2] == pytest.approx(0.2, abs=1e-6)
    assert m["run2"]["per_lamp_error_m"][2] == pytest.approx(0.1, abs=1e-6)
    assert m["run2"]["duplicates"] == 1 and m["run1"]["duplicates"] == 0


def test_map_underlay_and_missing_map(case: dict) -> None:
    out = case["root"] / "mapreport"
    r = _cli("evaluate", case["log"], case["run"], "-o", out, "--map", case["fgm"])
    assert r.returncode == 0, r.stderr
    assert (out / "fig1_paths.png").stat().st_size > 10_000
    bad = case["root"] / "nomapreport"
    r = _cli("evaluate", case["log"], case["run"], "-o", bad, "--map", case["root"] / "run")
    assert r.returncode == 3 and "map does not exist" in r.stderr and not bad.exists()


def test_tum_pair(case: dict) -> None:
    out = case["root"] / "tumreport"
    r = _cli("evaluate", case["truth_tum"], case["run"] / "trajectory.tum", "-o", out)
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert set(m["phases"]) == {"overall"}
    assert m["phases"]["overall"]["position_m"]["mean"] == pytest.approx(np.hypot(*OFFSET), 1e-4)


def test_recorded_log_truth_loses_its_stray_poses(case: dict) -> None:
    """A log without a scenario (a recorded one) whose ground truth topic holds three
    stray copies of its first pose: they are dropped and counted; the same poses in a
    simulated log (with a scenario) are kept."""
    from fuzzyslam.evaluation.evaluate import read_truth

    t = np.arange(0.0, 60.0, 0.05)  # a circle of 2 m radius in 60 s, at 20 Hz
    a = 2 * np.pi * t / 60.0
    truth = np.column_stack([2 * np.sin(a), 2 - 2 * np.cos(a), a])
    strays = [100, 300, 500]
    ts = np.concatenate([t, t[strays] + 0.025])
    ps = np.vstack([truth, np.repeat(truth[:1], len(strays), 0)])
    order = np.argsort(ts)
    log = case["root"] / "recorded.mcap"
    with LogWriter(log) as w:
        for ti, p in zip(ts[order], ps[order], strict=True):
            w.write("/ground_truth/odom", ODOMETRY, odometry(ti, "map", "base_link", p), ti)
    tr = read_truth(log, progress=False)
    assert tr.lines_dropped == len(strays) and tr.t.size == t.size
    sim = read_truth(case["log"], progress=False)
    assert sim.lines_dropped is None


def test_help_says_a_real_log_with_ground_truth_is_a_truth(tmp_path: Path) -> None:
    """``evaluate --help`` says TRUTH may be any log with /ground_truth/odom, not only a
    simulated one, as it is: the committed MRCLAM excerpt (a real log) against its own
    truth.tum gives sub-millimetre errors."""
    r = _cli("evaluate", "--help")
    assert r.returncode == 0, r.stderr
    text = " ".join(r.stdout.split())
    assert "/ground_truth/odom" in text and "or a real one" in text, text
    excerpt = Path(__file__).resolve().parents[1] / "data" / "real" / "mrclam6_excerpt"
    r = _cli("evaluate", excerpt / "log.mcap", excerpt / "truth.tum", "-o", tmp_path / "rep")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["ape_rmse_m"] < 0.005


@pytest.mark.parametrize(
    ("truth", "est", "needle"),
    [
        ("nogt", "run", "no ground truth"),
        ("log", "late", "does not overlap"),
        ("junk", "run", "unknown file kind"),
        ("log", "junk", "unknown file kind"),
        ("log", "root", "no trajectory.tum"),
        ("run", "run", "TRUTH must be"),
        ("log", "log", "ESTIMATE must be"),
    ],
)
def test_bad_inputs_one_line_exit3_nothing_written(
    case: dict, truth: str, est: str, needle: str
) -> None:
    out = case["root"] / f"bad_{truth}_{est}"
    r = _cli("evaluate", case[truth], case[est], "-o", out)
    assert r.returncode == 3
    assert needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert r.stdout == ""
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]


def test_compare_side_by_side(case: dict) -> None:
    """--compare: a second estimate (truth shifted by twice the offset) is evaluated alike;
    its row equals its own evaluation, the main one comes first, the figure is drawn."""
    from fuzzyslam.streams.tum import read_tum, write_tum

    t, poses = read_tum(case["truth_tum"])
    shifted = poses.copy()
    shifted[:, :2] += 2.0 * np.asarray(OFFSET)
    other = case["root"] / "shifted.tum"
    write_tum(other, t, shifted)
    out = case["root"] / "compare"
    r = _cli("evaluate", case["log"], case["run"], "-o", out, "--compare", other)
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    rows = m["comparison"]
    assert [x["label"] for x in rows] == [m["label"], "shifted"]
    off = float(np.hypot(*OFFSET))
    assert rows[0]["phases"]["overall"]["position_mean_m"] == pytest.approx(off, abs=1e-5)
    assert rows[1]["phases"]["overall"]["position_mean_m"] == pytest.approx(2 * off, abs=1e-5)
    assert rows[1]["lamps_duplicated"] is None  # a TUM file carries no lamps
    alone = case["root"] / "shifted_alone"
    assert _cli("evaluate", case["log"], other, "-o", alone).returncode == 0
    a = json.loads((alone / "metrics.json").read_text())["phases"]
    for name, b in rows[1]["phases"].items():
        assert b["position_max_m"] == pytest.approx(a[name]["position_m"]["max"], abs=1e-12)
        assert b["heading_mean_deg"] == pytest.approx(a[name]["heading_deg"]["mean"], abs=1e-12)
    md = (out / "report.md").read_text()
    assert "## Side by side" in md and "| after | shifted |" in md
    assert (out / "compare.png").stat().st_size > 10_000 and "(compare.png)" in md
    bad = case["root"] / "compare_bad"
    r = _cli("evaluate", case["log"], case["run"], "-o", bad, "--compare", case["late"])
    assert r.returncode == 3 and "does not overlap" in r.stderr and str(case["late"]) in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not bad.exists()


def test_compare_labels(case: dict) -> None:
    """--compare LABEL=PATH names the compared estimate in metrics, report and figure; a
    path that exists as written (even with '=' in its name) stays a path; the reproduce
    plan names its compared runs by their report labels, not their folder names."""
    from fuzzyslam.evaluation.evaluate import split_label
    from fuzzyslam.reproduce.plan import COMPARE, compare_label

    odd = case["root"] / "a=b.tum"
    odd.write_bytes(case["truth_tum"].read_bytes())
    assert split_label(str(odd)) == (None, str(odd))
    assert split_label("lamps only=runs/AB") == ("lamps only", "runs/AB")
    assert split_label("runs/x=AB") == (None, "runs/x=AB")  # a separator: not a label
    out = case["root"] / "compare_labels"
    r = _cli("evaluate", case["log"], case["run"], "-o", out, "--compare", f"truth copy={odd}")
    assert r.returncode == 0, r.stderr
    rows = json.loads((out / "metrics.json").read_text())["comparison"]
    assert rows[1]["label"] == "truth copy"
    assert rows[1]["phases"]["overall"]["position_mean_m"] == pytest.approx(0.0, abs=1e-9)
    assert "| truth copy |" in (out / "report.md").read_text()
    labels = {compare_label(o) for v in COMPARE.values() for o in v}
    assert labels and not labels & {o for v in COMPARE.values() for o in v}
