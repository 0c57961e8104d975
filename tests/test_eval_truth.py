"""evaluate's truth: its stray lines dropped (the odometry glitch gate, one rule with
benchmarks/bench_buildings.py), truth.tum written in the estimate's frame (evo without
alignment gives the reported APE), and the estimate called overconfident when its NEES
against the truth is far beyond chi-square."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from fuzzyslam import se2
from fuzzyslam.evaluation.consistency import Consistency, overconfident
from fuzzyslam.evaluation.core import (
    MAX_STRAY_SHARE,
    Estimate,
    Truth,
    drop_stray_truth,
    evaluate,
)
from fuzzyslam.evaluation.evaluate import read_truth, run_evaluate
from fuzzyslam.evaluation.params import EvalParams
from fuzzyslam.streams.tum import read_tum, write_tum

ROOT = Path(__file__).resolve().parents[1]
EXCERPT = ROOT / "data" / "real" / "mrclam6_excerpt"
REAL = ROOT.parent / "shared" / "data" / "real"  # the shared logs, when present


def _loop(hz: float = 10.0, seconds: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """A robot driving an ellipse at about 0.4 m/s, Unix-like stamps."""
    t = 1.6e9 + np.arange(0.0, seconds, 1.0 / hz)
    a = 2 * np.pi * (t - t[0]) / seconds
    xy = np.column_stack([3.0 * np.cos(a), 2.0 * np.sin(a)])
    th = np.arctan2(2.0 * np.cos(a), -3.0 * np.sin(a))
    return t, np.column_stack([xy, th])


def _with_strays(t: np.ndarray, p: np.ndarray, at: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """The CARMEN pattern: a copy of the first pose inserted half-way between lines k and
    k + 1 for each k in ``at`` (metres away, and back at the next line)."""
    ts = np.concatenate([t, 0.5 * (t[at] + t[np.add(at, 1)])])
    ps = np.vstack([p, np.repeat(p[:1], len(at), axis=0)])
    order = np.argsort(ts)
    return ts[order], ps[order]


STRAYS = [40, 130, 250, 420]


def test_stray_truth_lines_dropped_counted_and_warned(tmp_path: Path) -> None:
    """A truth at 10 Hz with four stray copies of its first pose, an estimate at 20 Hz
    exactly on the true path: nothing but the strays is dropped, the errors vanish, and
    the summary counts and warns. (Kept, each stray pulls the estimates next to it metres
    away.)"""
    t, p = _loop()
    ts, ps = _with_strays(t, p, STRAYS)
    kt, kp, dropped, refused = drop_stray_truth(ts, ps)
    assert dropped == refused == len(STRAYS)
    assert np.array_equal(kt, t) and np.array_equal(kp, p)
    write_tum(tmp_path / "truth.tum", ts, ps)
    truth = read_truth(tmp_path / "truth.tum", progress=False)
    assert truth.lines_dropped == len(STRAYS) and truth.t.size == t.size
    te = np.arange(t[0], t[-1], 0.05)
    est = Estimate(te, se2.interpolate_poses(t, p, te), label="est")
    ev = evaluate(truth, est, EvalParams())
    m = ev.metrics
    assert m["phases"]["overall"]["position_m"]["max"] < 0.05  # the chord of 0.1 s
    assert m["truth_lines_dropped"] == len(STRAYS)
    assert m["headline"]["truth_lines_dropped"] == len(STRAYS)
    assert any("4 stray truth line(s) dropped" in w for w in m["warnings"])


def test_clean_truth_nothing_dropped_nothing_warned(tmp_path: Path) -> None:
    """A truth without strays: no line dropped, no warning; a simulated log's truth is
    not checked (no key)."""
    t, p = _loop()
    write_tum(tmp_path / "truth.tum", t, p)
    truth = read_truth(tmp_path / "truth.tum", progress=False)
    assert truth.lines_dropped == 0
    m = evaluate(truth, Estimate(t, p.copy()), EvalParams()).metrics
    assert m["truth_lines_dropped"] == 0 and m["warnings"] == []
    sim = evaluate(Truth(t, p), Estimate(t, p.copy()), EvalParams()).metrics
    assert "truth_lines_dropped" not in sim


def test_too_many_refusals_are_not_strays() -> None:
    """A truth faster than the gate's limits (a car at 10 m/s): the gate refuses most of
    it, which is not a few glitches, so every line is kept."""
    t = 1.6e9 + np.arange(0.0, 30.0, 0.1)
    p = np.column_stack([10.0 * (t - t[0]), np.zeros_like(t), np.zeros_like(t)])
    kt, _, dropped, refused = drop_stray_truth(t, p)
    assert dropped == 0 and refused > 0.5 * t.size and kt.size == t.size


def _noisy_estimate(scale_cov: float) -> tuple[Truth, Estimate]:
    """An estimate whose errors are drawn from its covariance times 1 / ``scale_cov``."""
    t, p = _loop(hz=20.0, seconds=120.0)
    rng = np.random.default_rng(3)
    cov = np.diag([0.02**2, 0.03**2, np.radians(1.0) ** 2])
    err = rng.multivariate_normal(np.zeros(3), cov, size=t.size)
    est = p + err
    est[:, 2] = se2.wrap_angle(est[:, 2])
    covs = np.repeat((cov * scale_cov)[None], t.size, axis=0)
    return Truth(t, p), Estimate(t, est, cov=covs)


def test_overconfidence_warned_only_when_gross() -> None:
    """Errors drawn from the stated covariance: NEES mean about 3, no warning; the same
    with the covariance shrunk 100 times: NEES about 300, warned with its mean and the
    share above 100."""
    truth, ok = _noisy_estimate(1.0)
    m = evaluate(truth, ok, EvalParams()).metrics
    assert m["phases"]["overall"]["nees"]["mean"] == pytest.approx(3.0, rel=0.1)
    assert not [w for w in m["warnings"] if "overconfident" in w]
    _, bad = _noisy_estimate(0.01)
    m = evaluate(truth, bad, EvalParams()).metrics
    nees = m["phases"]["overall"]["nees"]
    assert nees["mean"] == pytest.approx(300.0, rel=0.1)
    (w,) = [w for w in m["warnings"] if "overconfident" in w]
    assert f"NEES mean {nees['mean']:.3g} (3 expected" in w
    assert f"above 100 for {100 * nees['frac_above_100']:.0f} % of the compared" in w
    assert m["headline"]["warnings"] == m["warnings"]


def test_a_short_truth_keeps_its_strays_dropped() -> None:
    """Ten seconds of truth with three strays (3 % of its lines, over the share a fast
    truth is told by): each came back, none ended in the gate's reset, so they are
    dropped all the same."""
    t, p = _loop(seconds=10.0)
    at = [20, 50, 80]
    ts, ps = _with_strays(t, p, at)
    assert len(at) > MAX_STRAY_SHARE * ts.size
    kt, kp, dropped, refused = drop_stray_truth(ts, ps)
    assert dropped == refused == len(at)
    assert np.array_equal(kt, t) and np.array_equal(kp, p)


def test_refusals_that_run_to_the_truth_s_end_are_kept() -> None:
    """A truth whose last lines really move away faster than the gate allows (refused to
    the end, never come back, no reset reached): they are not strays, every line kept."""
    t, p = _loop(seconds=10.0)
    p = p.copy()
    p[-5:, 0] += 20.0 * np.arange(1, 6)  # 20 m a line: far past the gate's limits
    kt, _, dropped, refused = drop_stray_truth(t, p)
    assert refused == 5 > MAX_STRAY_SHARE * t.size
    assert dropped == 0 and kt.size == t.size


def test_estimate_in_another_frame_is_said() -> None:
    """An estimate with the stated noise but written in its start pose's frame (the truth
    moved by 3 m and 40 deg): without --align, the frames are said (raw RMSE against the
    RMSE after one rigid motion), its NEES called overconfident too (a start heading off is
    both); with --align, or in the truth's own frame, nothing is said."""
    truth, est = _noisy_estimate(1.0)
    moved = Estimate(est.t, se2.compose(np.array([3.0, -1.0, 0.7]), est.poses), cov=est.cov)
    m = evaluate(truth, moved, EvalParams()).metrics
    ape = m["phases"]["overall"]["ape_m"]
    (w,) = [w for w in m["warnings"] if "another frame" in w]
    assert f"RMSE {ape['raw']['rmse']:.3g} m as written, {ape['aligned']['rmse']:.3g} m" in w
    assert ape["raw"]["rmse"] > 10 * ape["aligned"]["rmse"]
    assert [w for w in m["warnings"] if "overconfident" in w]
    for m in (
        evaluate(truth, moved, EvalParams(), align=True).metrics,
        evaluate(truth, est, EvalParams()).metrics,
    ):
        assert not [w for w in m["warnings"] if "another frame" in w or "overconfident" in w]


def test_overconfident_thresholds_are_chi_square_not_the_band() -> None:
    """Out of the 95 % band of the mean is not enough (the samples are correlated); the
    mean above one sample's 99.9 % quantile (16.27 for 3 dof), or over 5 % of the samples
    above 100, is."""

    def c(mean: float, above: float) -> Consistency:
        return Consistency(3, 1000, mean, 2.8, 3.2, False, 0.5, above)

    assert not overconfident(c(7.0, 0.0))  # a real MRCLAM run: out of band, not gross
    assert not overconfident(c(16.2, 0.04))
    assert overconfident(c(16.3, 0.0))
    assert overconfident(c(9.0, 0.06))
    assert not overconfident(Consistency(3, 0, float("nan"), 0, 0, False, float("nan")))


def _evo_ape_rmse(ref: Path, est: Path, align: bool) -> float:
    """evo's APE (translation part) of ``est`` against ``ref``, as ``evo_ape tum`` does it
    (its association of the stamps; with ``align``, its Umeyama alignment)."""
    evo_io = pytest.importorskip("evo.tools.file_interface")
    evo_sync = pytest.importorskip("evo.core.sync")
    evo_metrics = pytest.importorskip("evo.core.metrics")
    r = evo_io.read_tum_trajectory_file(str(ref))
    e = evo_io.read_tum_trajectory_file(str(est))
    r, e = evo_sync.associate_trajectories(r, e)
    if align:
        e.align(r, correct_scale=False)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((r, e))
    return float(ape.get_statistic(evo_metrics.StatisticsType.rmse))


def _check_evo(rep: Path, trajectory: Path) -> dict:
    """evo on evaluate's truth.tum and the run's trajectory.tum gives metrics.json's
    overall APE: raw without alignment, aligned with it (to the files' micrometres)."""
    m = json.loads((rep / "metrics.json").read_text())
    ape = m["phases"]["overall"]["ape_m"]
    raw = _evo_ape_rmse(rep / "truth.tum", trajectory, align=False)
    assert raw == pytest.approx(ape["raw"]["rmse"], abs=2e-6)
    assert raw == pytest.approx(m["headline"]["ape_rmse_m"], abs=2e-6)
    aligned = _evo_ape_rmse(rep / "truth.tum", trajectory, align=True)
    assert aligned == pytest.approx(ape["aligned"]["rmse"], abs=2e-6)
    return m


@pytest.mark.slow
def test_evo_reproduces_the_ape_of_an_aligned_estimate(tmp_path: Path) -> None:
    """An estimate in its own frame (the truth moved by 5 m and 120 deg, plus a drift):
    evaluated with --align, its truth.tum is in that frame, where evo without alignment
    gives the reported APE (before the fix truth.tum was in the truth's frame: evo gave
    metres). A truth without alignment is written as read."""
    t, p = _loop(hz=20.0, seconds=120.0)
    motion = np.array([5.0, -3.0, np.radians(120.0)])
    drift = np.column_stack([0.002 * (t - t[0]), np.zeros((t.size, 2))])
    est = se2.compose(np.repeat(motion[None], t.size, 0), p + drift)
    run = tmp_path / "run"
    run.mkdir()
    write_tum(run / "trajectory.tum", t, est)
    write_tum(tmp_path / "truth.tum", t, p)
    rep = tmp_path / "ev"
    run_evaluate(tmp_path / "truth.tum", run, rep, align=True)
    m = _check_evo(rep, run / "trajectory.tum")
    assert m["aligned_to_truth"]["theta_deg"] == pytest.approx(-120.0, abs=1.0)
    assert 0.01 < m["phases"]["overall"]["ape_m"]["raw"]["rmse"] < 0.2
    rep2 = tmp_path / "ev_plain"
    run_evaluate(tmp_path / "truth.tum", tmp_path / "truth.tum", rep2)
    assert np.allclose(read_tum(rep2 / "truth.tum")[1], p, atol=1e-6)
    _check_evo(rep2, tmp_path / "truth.tum")


def _run_excerpt(out: Path) -> None:
    from fuzzyslam.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["run", str(EXCERPT / "log.mcap"), "--config", "real_detections.yaml", "-o", str(out)])
    assert exc.value.code in (0, None)


def _evaluate_excerpt(run: Path, rep: Path) -> dict:
    run_evaluate(EXCERPT / "truth.tum", run, rep, landmarks_truth=EXCERPT / "landmarks_truth.yaml")
    return json.loads((rep / "metrics.json").read_text())


@pytest.mark.slow
def test_real_excerpt_evo_and_overconfidence(tmp_path: Path) -> None:
    """150 s of MRCLAM 6 (committed): evaluate's truth.tum and the run's trajectory.tum
    give the reported APE with plain evo; the run's NEES is not called overconfident, a
    copy of the run with its covariances shrunk 100 times is, in the summary and the
    report."""
    run = tmp_path / "run"
    _run_excerpt(run)
    m = _evaluate_excerpt(run, tmp_path / "ev")
    _check_evo(tmp_path / "ev", run / "trajectory.tum")
    assert m["aligned_to_truth"] and m["truth_lines_dropped"] == 0
    assert not [w for w in m["warnings"] if "overconfident" in w]
    shrunk = tmp_path / "shrunk"
    shutil.copytree(run, shrunk)
    lines = (shrunk / "covariance.csv").read_text().splitlines()
    rows = [lines[0]] + [
        ",".join([c[0], *(repr(float(v) / 100.0) for v in c[1:])])
        for c in (ln.split(",") for ln in lines[1:])
    ]
    (shrunk / "covariance.csv").write_text("\n".join(rows) + "\n")
    m2 = _evaluate_excerpt(shrunk, tmp_path / "ev_shrunk")
    nees = m2["phases"]["overall"]["nees"]
    assert nees["mean"] == pytest.approx(100 * m["phases"]["overall"]["nees"]["mean"], rel=1e-6)
    (w,) = [w for w in m2["warnings"] if "overconfident" in w]
    assert w in (tmp_path / "ev_shrunk" / "report.md").read_text()


@pytest.mark.parametrize(("name", "dropped"), [("carmen-aces", 21), ("carmen-fr079", 17)])
def test_shared_carmen_truths_lose_their_strays(name: str, dropped: int) -> None:
    """The CARMEN conversions' truth.tum (shared logs; skipped without them): the stray
    copies of the first pose are dropped, as bench_buildings.py counts them."""
    truth = REAL / name / "truth.tum"
    if not truth.is_file():
        pytest.skip(f"{truth} not here (the shared real logs)")
    tr = read_truth(truth, progress=False)
    assert tr.lines_dropped == dropped
    t, _ = read_tum(truth)
    assert tr.t.size == t.size - dropped
