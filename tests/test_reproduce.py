"""``fuzzyslam reproduce``: the plan, the table over seeds, and the quick experiment end to end."""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import shared_dir

from fuzzyslam.reproduce.execute import StepFailed, execute
from fuzzyslam.reproduce.plan import (
    EVALUATIONS,
    FULL,
    QUICK,
    Step,
    build_plan,
    compare_label,
    critical_path,
    ready_order,
)
from fuzzyslam.reproduce.table import CAL, ROWS, Row, aggregate, phase_stat, run_labels

pytestmark = pytest.mark.slow  # end to end: the quick reproduce fixture runs every stage


def cli(*args: object, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "fuzzyslam", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "MPLBACKEND": "Agg"},
    )


# --- plan (pure) ---------------------------------------------------------------------------


def test_plan_every_input_is_made_by_an_earlier_dependency():
    """Each file a step reads is written by one of its (transitive) dependencies."""
    steps = build_plan([0, 3], FULL)
    by_key = {s.key: s for s in steps}
    outputs = {}
    for s in steps:
        i = s.argv.index("-o") + 1
        outputs[s.argv[i]] = s.key

    def ancestors(k: str) -> set[str]:
        out: set[str] = set()
        todo = list(by_key[k].deps)
        while todo:
            d = todo.pop()
            if d not in out:
                out.add(d)
                todo.extend(by_key[d].deps)
        return out

    for s in steps:
        anc = ancestors(s.key)
        own = s.argv[s.argv.index("-o") + 1]
        reads = [a for a in s.argv[1:] if a.startswith("seed") and a != own]
        for path in reads:
            producer = outputs.get(path) or outputs.get(str(Path(path).parent))
            assert producer is not None, f"{s.key} reads {path} that no step writes"
            assert producer in anc, f"{s.key} reads {path} before {producer} ran"
    # one evaluation per estimate of EVALUATIONS and per seed, seeds kept apart
    assert sum(s.kind == "evaluate" for s in steps) == 2 * len(EVALUATIONS)
    for s in steps:
        if s.kind == "simulate":
            assert s.key.split("/")[0] == f"seed{s.argv[s.argv.index('--seed') + 1]}"


def test_plan_uses_the_suite_configs():
    quick = build_plan([0], QUICK)
    sims = {s.argv[1] for s in quick if s.kind == "simulate"}
    assert sims == {QUICK.paper, QUICK.bumps, QUICK.dark, QUICK.people}
    # a run reads its log with the config it was simulated from
    for s in quick:
        if s.kind == "run":
            log = Path(s.argv[1]).stem
            assert s.argv[s.argv.index("--config") + 1] == getattr(QUICK, log)


def test_critical_path_is_the_longest_chain():
    """On a hand-made graph: a(1) -> b(5) -> d(1), a -> c(2) -> d: from a, 1 + 5 + 1 = 7."""
    steps = [
        Step("a", ("x",), (), 1.0),
        Step("b", ("x",), ("a",), 5.0),
        Step("c", ("x",), ("a",), 2.0),
        Step("d", ("x",), ("b", "c"), 1.0),
    ]
    cp = critical_path(steps)
    assert cp == {"a": 7.0, "b": 6.0, "c": 3.0, "d": 1.0}


def test_the_plan_starts_the_longest_chain_first():
    """On the full plan: once the paper's FGM is done, phase D (heading fixes over all six
    runs of the bump log, --fix-from 0) outranks every other ready step, as its chain
    (D, then eval_D) is the longest left; the order is the same on every call and does
    not depend on the order the steps are listed in."""
    steps = build_plan([0], FULL)
    prio = critical_path(steps)
    by = {s.key.split("/")[1]: s for s in steps}
    # D's chain: its run (the aid over 6 runs, not 2) and its evaluation
    assert prio["seed0/D"] == pytest.approx(by["D"].cost + by["eval_D"].cost)
    assert by["D"].cost > 1.8 * by["C"].cost
    ready = [by[k] for k in ("C", "C_pose", "dark_heading", "dark_pose", "people_pose", "D",
                             "eval_AB")]  # fmt: skip
    order = [s.key.split("/")[1] for s in ready_order(ready, prio)]
    assert order[0] == "D" and order[-1] == "eval_AB"
    assert order == [s.key.split("/")[1] for s in ready_order(ready[::-1], prio)]
    # a step never ranks below a step it leads to (a chain is at least its own length)
    for s in steps:
        for d in s.deps:
            assert prio[d] > prio[s.key]


def test_plan_refuses_unknown_dependencies_and_cycles():
    with pytest.raises(ValueError, match="cycle"):
        critical_path([Step("a", ("x",), ("b",)), Step("b", ("x",), ("a",))])


# --- table (pure) --------------------------------------------------------------------------


def _seed(a_pos: float, c_after: float, c_a: float) -> dict:
    return {
        "eval": {
            "AB": {"freeze_run": 4, "phases": {"A": {"runs": [1, 2, 3, 4],
                   "position_m": {"mean": a_pos}}, "after": {"runs": [5, 6]}}},
            "C": {"phases": {"A": {"position_m": {"mean": c_a}},
                             "after": {"position_m": {"mean": c_after}}}},
        },
        "run": {},
        "seconds": 10.0,
    }  # fmt: skip


def test_aggregate_mean_spread_and_target_over_seeds():
    """Known answers: values 0.01, 0.02, 0.04 m -> 1, 2, 4 cm; mean 7/3; sample std
    sqrt(((1-7/3)^2 + (2-7/3)^2 + (4-7/3)^2) / 2); target <= 3 cm met in 2 of 3 seeds."""
    row = Row("A", "pos", "-", "<= 3 cm", phase_stat("AB", "A", "position_m", "mean", scale=100.0),
              "cm", lambda v: v <= 3.0)  # fmt: skip
    results = [_seed(0.01, 0, 1), _seed(0.02, 0, 1), _seed(0.04, 0, 1)]
    (agg,) = aggregate(results, (row,))
    assert agg.values == pytest.approx((1.0, 2.0, 4.0))
    assert agg.mean == pytest.approx(7 / 3)
    m = 7 / 3
    assert agg.spread == pytest.approx(math.sqrt(((1 - m) ** 2 + (2 - m) ** 2 + (4 - m) ** 2) / 2))
    assert agg.met == (2, 3)


def test_a_missing_metric_is_none_not_zero():
    ratio_row = next(r for r in ROWS if r.measure == "ratio to phase A")
    results = [_seed(0.01, 0.03, 0.02), {"eval": {}, "run": {}, "seconds": 1.0}]  # no C
    (agg,) = aggregate(results, (ratio_row,))
    assert agg.values[0] == pytest.approx(1.5)
    assert agg.values[1] is None
    assert agg.mean == pytest.approx(1.5) and agg.spread is None


def test_run_labels_follow_the_phases():
    lab = run_labels(_seed(0.01, 0, 1))
    assert lab == {"A": "runs 1-4", "after": "runs 5-6", "all": "runs 1-6", "freeze": "4",
                   "last": "6"}  # fmt: skip


# --- execution ----------------------------------------------------------------------------


def test_a_failing_step_stops_the_plan_with_its_one_line_error(tmp_path):
    """The step's own error (naming the file) and exit code come back; later steps never run."""
    steps = [
        Step(
            "s/run",
            ("run", "missing.mcap", "-o", "est"),
            (),
            1.0,
            "run",
            (("log", "missing.mcap"), ("outdir", "est")),
        ),
        Step(
            "s/eval",
            ("evaluate", "missing.mcap", "est", "-o", "ev"),
            ("s/run",),
            1.0,
            "evaluate",
            (("truth", "missing.mcap"), ("estimate", "est"), ("outdir", "ev")),
        ),
    ]
    with pytest.raises(StepFailed) as info:
        execute(steps, tmp_path, jobs=1)
    assert info.value.exit_code == 3
    msg = str(info.value)
    assert "s/run" in msg and "missing.mcap" in msg and "\n" not in msg
    assert not (tmp_path / "est").exists() and not (tmp_path / "ev").exists()


def test_reproduce_output_in_missing_directory_is_one_line(tmp_path):
    p = cli("reproduce", "--quick", "--seeds", "1", "-o", tmp_path / "no" / "out")
    assert p.returncode == 3
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("fuzzyslam:")]
    assert len(lines) == 1 and "does not exist" in lines[0], p.stderr
    assert not (tmp_path / "no").exists()


# --- the quick experiment, end to end ------------------------------------------------------


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory) -> tuple[Path, dict]:
    """``reproduce --quick --seeds 1`` once per test run (conftest.shared_dir)."""

    def build(root: Path) -> None:
        p = cli("reproduce", "--quick", "--seeds", "1", "-o", root / "out", "--jobs", "2")
        assert p.returncode == 0, p.stderr
        (root / "stdout.json").write_text(p.stdout)

    root = shared_dir(tmp_path_factory, "quick-reproduce", build)
    return root / "out", json.loads((root / "stdout.json").read_text())


def test_quick_reproduce_report_has_every_row_with_a_number(quick_run):
    out, summary = quick_run
    assert Path(summary["report"]) == out / "report.md"
    report = (out / "report.md").read_text()
    results = json.loads((out / "results.json").read_text())
    labels = results["labels"]
    table = [ln for ln in report.splitlines() if ln.startswith("| ") and ln.count("|") == 7]
    for row in ROWS:
        measure = row.measure.format(**labels)
        hits = [ln for ln in table if f"| {row.group} | {measure} |" in ln]
        assert len(hits) == 1, f"row missing from report.md: {row.group}: {measure}"
        value = hits[0].split("|")[5].strip()
        assert re.match(r"^-?\d", value), f"{row.group}: {measure} has no value: {value!r}"
    assert len(results["rows"]) == len(ROWS)
    # the shipped configs calibrate the odometry (paper.yaml): the calibration rows are
    # figures, the per-seed ones with a 2-sigma target counted
    cal = [r for r in results["rows"] if r["group"] == CAL]
    assert cal and all(r["mean"] is not None for r in cal)
    assert any(r["met"] is not None for r in cal)
    assert results["info"]["overrides"] == {}
    assert not list(out.glob("set_*.yaml"))


def test_quick_reproduce_table_agrees_with_the_evaluations(quick_run):
    """The table is read from the steps' metrics.json, not computed on the side."""
    out, _ = quick_run
    rows = {r["group"] + ": " + r["measure"]: r for r in json.loads(
        (out / "results.json").read_text())["rows"]}  # fmt: skip
    ab = json.loads((out / "seed0" / "eval_AB" / "metrics.json").read_text())
    c = json.loads((out / "seed0" / "eval_C" / "metrics.json").read_text())
    a_pos = rows["A. SLAM and map building: mean position error, {A}"]["mean"]
    assert a_pos == pytest.approx(100 * ab["phases"]["A"]["position_m"]["mean"])
    ratio = rows["C. lamp failure with Hough: ratio to phase A"]["mean"]
    pa, pc = c["phases"]["A"]["position_m"]["mean"], c["phases"]["after"]["position_m"]["mean"]
    assert ratio == pytest.approx(pc / pa)
    # the paper's phase A target, on the quick scenario too
    assert a_pos < 5.0
    # every lamp off: pose fixes, heading fixes and none side by side in one evaluation
    # (evaluate --compare), each row the same as the estimate's own evaluation
    dark = json.loads((out / "seed0" / "eval_dark_pose" / "metrics.json").read_text())
    cmp = {r["label"]: r["phases"]["after"]["position_mean_m"] for r in dark["comparison"]}
    labels = [compare_label(o) for o in ("dark_heading", "dark_none")]  # not folder names
    assert list(cmp)[1:] == labels
    for other, label in zip(("dark_heading", "dark_none"), labels, strict=True):
        own = json.loads((out / "seed0" / f"eval_{other}" / "metrics.json").read_text())
        assert cmp[label] == pytest.approx(own["phases"]["after"]["position_m"]["mean"])
    assert "## Side by side" in (out / "seed0" / "eval_dark_pose" / "report.md").read_text()


def test_quick_reproduce_writes_the_chain_as_commands_and_figures(quick_run):
    out, _ = quick_run
    cmds = (out / "commands.sh").read_text().splitlines()
    for verb in ("simulate", "run", "map", "evaluate"):
        assert any(c.startswith(f"fuzzyslam {verb} ") for c in cmds), verb
    assert any("--fix heading" in c for c in cmds) and any("--fix pose" in c for c in cmds)
    report = (out / "report.md").read_text()
    for rel in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", report):
        assert (out / rel).is_file(), rel
    assert (out / "summary.png").stat().st_size > 10_000
    assert not list(out.parent.glob(".*.part"))


@pytest.fixture(scope="module")
def calibrated_run(tmp_path_factory) -> Path:
    """``reproduce --quick --paper-only --seeds 1 --set robot.base_scale=1.02`` once: the
    simulator's wheel base 2 % off instead of the configs' 1 %."""

    def build(root: Path) -> None:
        p = cli("reproduce", "--quick", "--paper-only", "--seeds", "1", "-o", root / "out",
                "--jobs", "2", "--set", "robot.base_scale=1.02")  # fmt: skip
        assert p.returncode == 0, p.stderr

    return shared_dir(tmp_path_factory, "quick-reproduce-calibrated", build) / "out"


def test_calibration_rows_are_the_calibration_files_against_the_configs_truth(calibrated_run):
    """With ``--set robot.base_scale=1.02`` the steps name set_*.yaml configs (that
    calibrate, as the shipped ones do) with that truth, and the table's calibration rows
    are the map's and the C and D runs' calibration.yaml against the simulator's
    robot.*_scale of those configs, computed here from the files: the factors,
    (c - truth) / sigma and the largest of its magnitudes; the target met where that is
    at most 2."""
    import yaml

    from fuzzyslam.config import load_config

    out = calibrated_run
    results = json.loads((out / "results.json").read_text())
    assert results["info"]["overrides"] == {"robot.base_scale": 1.02}
    assert "--set robot.base_scale=1.02" in results["info"]["command"]
    cmds = (out / "commands.sh").read_text()
    assert "--set robot.base_scale=1.02" in cmds and "--config set_quick_failures.yaml" in cmds
    assert "--config quick_failures.yaml" not in cmds
    labels = results["labels"]
    rows = {r["measure"].format(**labels): r for r in results["rows"] if r["group"] == CAL}
    freeze = labels["freeze"]
    for log, cfg in (("paper", "set_quick_failures.yaml"), ("bumps", "set_quick_bumps.yaml")):
        robot = load_config(str(out / cfg)).robot
        truth = np.array([robot.left_scale, robot.right_scale, robot.base_scale])
        assert truth[2] == 1.02
        for est, measure in (("fgm", f"the map's at the end of run {freeze}"),
                             ("C", "end of phase C (heading fixes)"),
                             ("D", "end of phase D (bumps)")):  # fmt: skip
            if (est == "D") != (log == "bumps"):
                continue
            d = yaml.safe_load((out / "seed0" / est / "calibration.yaml").read_text())
            assert d["names"] == ["left_scale", "right_scale", "base_scale"]
            err = (np.array(d["factors"]) - truth) / np.array(d["sigma"])
            worst = rows[f"largest abs. error of s_L, s_R, s_B, {measure}"]
            assert worst["values"] == [pytest.approx(np.abs(err).max(), rel=1e-12)]
            assert worst["met"] == [int(np.abs(err).max() <= 2.0), 1]
            if est != "fgm":
                continue
            for i, (name, sym) in enumerate((("left wheel scale", "s_L"),
                                             ("right wheel scale", "s_R"),
                                             ("wheel-base scale", "s_B"))):  # fmt: skip
                assert rows[f"{name} {sym}, the simulator's truth"]["values"] == [truth[i]]
                got = rows[f"{name} {sym}, {measure}"]["values"]
                assert got == [d["factors"][i]]
                got = rows[f"{sym} error, {measure}"]["values"]
                assert got == [pytest.approx(err[i], rel=1e-12)]
    # the table's figures are those of benchmarks/calibration_vs_truth.py's lines
    bench = Path(__file__).resolve().parents[1] / "benchmarks" / "calibration_vs_truth.py"
    cfg = str(out / "set_quick_failures.yaml")
    p = subprocess.run([sys.executable, str(bench), str(out), "--config", cfg],
                       capture_output=True, text=True)  # fmt: skip
    assert p.returncode == 0, p.stderr
    line = next(ln for ln in p.stdout.splitlines() if ln.startswith("seed0 | fgm |"))
    errs = [float(v) for v in line.split("|")[5].split(",")]
    got = [rows[f"{s} error, the map's at the end of run {freeze}"]["values"][0]
           for s in ("s_L", "s_R", "s_B")]  # fmt: skip
    assert got == pytest.approx(errs, abs=0.006)


def test_paper_only_plan_is_the_paper_phases_subset():
    full = {s.key: s for s in build_plan([0], FULL)}
    paper = build_plan([0], FULL, beyond=False)
    assert {s.key for s in paper} < set(full)
    assert all(full[s.key] == s for s in paper)
    assert {s.argv[1] for s in paper if s.kind == "simulate"} == {FULL.paper, FULL.bumps}
    assert not any("pose" in s.argv for s in paper)
    assert {s.key.split("/")[1] for s in paper if s.kind == "evaluate"} == {
        "eval_AB", "eval_C", "eval_D"
    }  # fmt: skip


def test_reference_angle_rows_read_the_map_summary():
    """Errors -0.2, 0.1, 0.05 deg: mean of |e| 0.35 / 3, largest 0.2; a seed without a map
    summary gives None; a map summary without reference_truth is an error, not a blank."""
    from fuzzyslam.reproduce.table import MissingMetric, SeedResult, reference_error

    truth = [{"error_deg": -0.2}, {"error_deg": 0.1}, {"error_deg": 0.05}]
    r = SeedResult(0, map={"fgm": {"reference_truth": truth}})
    assert reference_error("mean")(r) == pytest.approx(0.35 / 3)
    assert reference_error("max")(r) == pytest.approx(0.2)
    assert reference_error("max")(SeedResult(0)) is None
    with pytest.raises(MissingMetric):
        reference_error("max")(SeedResult(0, map={"fgm": {"references": []}}))


def test_no_row_text_breaks_the_markdown_table():
    for row in ROWS:
        for text in (row.group, row.measure, row.paper, row.target, row.unit):
            assert "|" not in text, text
