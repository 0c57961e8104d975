"""The reproduce headline JSON carries its units (issue 17): every key ends with one."""

from __future__ import annotations

import json

import pytest

from fuzzyslam.reproduce.report import write_results
from fuzzyslam.reproduce.table import (
    HEADLINE_UNITS,
    ROWS,
    Row,
    aggregate,
    headline_key,
    unit_suffix,
)

LABELS = {"A": "runs 1-4", "after": "runs 5-6", "all": "runs 1-6", "freeze": "4", "last": "6"}


def test_every_headline_key_ends_with_a_unit() -> None:
    keys = [headline_key(r, LABELS) for r in ROWS]
    assert len(set(keys)) == len(ROWS)
    for row, key in zip(ROWS, keys, strict=True):
        assert any(key.endswith(f"_{u}") for u in HEADLINE_UNITS), key
        if row.unit:  # the unit shown in the table is the key's
            assert key.endswith(f"_{row.unit}"), key
    assert {unit_suffix(r) for r in ROWS} >= {"cm", "deg", "x", "count", "ratio"}


def test_results_rows_carry_the_headline_keys(tmp_path, monkeypatch) -> None:
    """results.json's rows name the same keys as the headline (and the same means)."""
    from fuzzyslam.reproduce import report

    monkeypatch.setattr(report, "run_labels", lambda _r: LABELS)
    aggs = aggregate([{"seed": 0, "seconds": 1.0}])
    write_results(tmp_path / "results.json", aggs, [{"seed": 0, "seconds": 1.0}], {}, [])
    rows = json.loads((tmp_path / "results.json").read_text())["rows"]
    assert [r["key"] for r in rows] == [headline_key(a.row, LABELS) for a in aggs]


def test_a_row_with_an_unknown_unit_is_refused() -> None:
    import pytest

    row = Row("g", "m", "-", "-", lambda _r: 1.0, "furlong")
    with pytest.raises(ValueError, match="furlong"):
        unit_suffix(row)


def test_every_row_reads_results_of_the_plan_and_a_missing_key_is_an_error():
    """A seed whose evaluations, runs and map are in the plan but hold nothing: every row
    but the seed's time raises MissingMetric (a renamed metric is an error, not a blank
    cell), so no row reads an evaluation or run the plan does not make."""
    from fuzzyslam.reproduce.plan import EVALUATIONS, QUICK, build_plan
    from fuzzyslam.reproduce.table import ROWS, MissingMetric, SeedResult

    runs = {s.key.split("/", 1)[1]: {} for s in build_plan([0], QUICK) if s.kind == "run"}
    truth = {"paper": [1.0, 1.0, 1.0], "bumps": [1.0, 1.0, 1.0]}  # the runs calibrate
    empty = SeedResult(0, {k: {} for k in EVALUATIONS}, runs, {"fgm": {}}, 1.0, truth)
    for row in ROWS:
        if row.measure.startswith("time of one seed") or row.measure.endswith("truth"):
            assert row.get(empty) == 1.0
            continue
        with pytest.raises(MissingMetric):
            row.get(empty)


def test_a_null_metric_is_a_blank_and_an_evaluation_outside_the_plan_too():
    from fuzzyslam.reproduce.table import SeedResult, phase_stat

    get = phase_stat("AB", "A", "position_m", "mean")
    assert get(SeedResult(0, {"AB": {"phases": {"A": {"position_m": None}}}})) is None
    assert get(SeedResult(0, {"AB": {"phases": {"A": {"position_m": {"mean": 0.02}}}}})) == 0.02
    assert get(SeedResult(0, {"C": {}})) is None  # --paper-only: no such evaluation


def test_calibration_rows_against_the_truth_and_n_a_without_calibration():
    """Known answers: factors (1.001, 0.999, 1.02), sigmas (0.001, 0.002, 0.004), truth
    (1.0004, 0.9996, 1.01): errors 0.6, -0.3, 2.5 sigma, the largest 2.5 (target missed);
    a run's summary is read alike. Without a truth (calibration off) every row is n/a,
    even where a summary has a calibration; with one but no calibration in the summary,
    MissingMetric."""
    from fuzzyslam.reproduce.table import CAL, MissingMetric, SeedResult, calibration

    rows = tuple(r for r in ROWS if r.group == CAL)

    entry = {"names": ["left_scale", "right_scale", "base_scale"],
             "factors": [1.001, 0.999, 1.02], "sigma": [0.001, 0.002, 0.004]}  # fmt: skip
    truth = [1.0004, 0.9996, 1.01]
    r = SeedResult(0, run={"D": {"calibration": entry}}, map={"fgm": {"calibration": entry}},
                   calibration_truth={"paper": truth, "bumps": truth})  # fmt: skip
    assert [calibration("fgm", "error", i)(r) for i in range(3)] == pytest.approx([0.6, -0.3, 2.5])
    assert calibration("fgm", "factor", 2)(r) == 1.02
    assert calibration("fgm", "truth", 0)(r) == 1.0004
    assert calibration("D", "worst")(r) == pytest.approx(2.5)
    assert calibration("C", "worst")(r) is None  # C not in these results
    (worst,) = [x for x in aggregate([r], rows) if x.row.measure.startswith("largest abs. error")
                and "phase D" in x.row.measure]  # fmt: skip
    assert worst.met == (0, 1)
    off = SeedResult(0, run={"D": {"calibration": entry}}, map={"fgm": {"calibration": entry}})
    aggs = aggregate([off], rows)
    assert len(aggs) == 12 and all(a.mean is None and a.met is None for a in aggs)
    with pytest.raises(MissingMetric):
        calibration("fgm", "error", 0)(SeedResult(0, map={"fgm": {}},
                                                  calibration_truth={"paper": truth}))  # fmt: skip
    # another odometry model (Odometry poses: no true wheels): n/a
    odom = {"names": ["trans_scale", "rot_scale"], "factors": [1.0, 1.0], "sigma": [0.1, 0.1]}
    r2 = SeedResult(0, map={"fgm": {"calibration": odom}}, calibration_truth={"paper": truth})
    assert calibration("fgm", "worst")(r2) is None


def test_reproduce_set_is_one_value_per_key_in_every_config_of_the_suite(tmp_path):
    """``reproduce --set``: KEY=VALUE parsed as sweep's --set (YAML values), one value
    only; each suite config becomes a set_NAME file that extends it and loads with the
    key set and everything else as the embedded config."""
    from fuzzyslam.config import load_config
    from fuzzyslam.errors import InputError
    from fuzzyslam.reproduce.overrides import parse_one, set_options, suite_with
    from fuzzyslam.reproduce.plan import QUICK

    assert parse_one("slam.calibrate=true") == ("slam.calibrate", True)
    with pytest.raises(InputError, match="one value"):
        parse_one("slam.gate=9,16")
    with pytest.raises(InputError):
        parse_one("slam.calibrate")
    assert suite_with(QUICK, {}, tmp_path) is QUICK
    over = {"slam.calibrate": True, "robot.base_scale": 1.02}
    suite = suite_with(QUICK, over, tmp_path)
    assert suite.paper == "set_quick_failures.yaml" and (tmp_path / suite.people).is_file()
    for name in ("paper", "bumps", "dark", "people"):
        mine, base = (load_config(str(tmp_path / getattr(suite, name))),
                      load_config(getattr(QUICK, name)))  # fmt: skip
        assert mine.slam.calibrate and mine.robot.base_scale == 1.02
        mine.slam.calibrate, mine.robot.base_scale = base.slam.calibrate, base.robot.base_scale
        assert mine == base
    assert set_options(over) == " --set slam.calibrate=true --set robot.base_scale=1.02"
    with pytest.raises(Exception, match="nosuch"):
        suite_with(QUICK, {"slam.nosuch": 1}, tmp_path)
