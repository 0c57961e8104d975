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
    empty = SeedResult(0, {k: {} for k in EVALUATIONS}, runs, {"fgm": {}}, 1.0)
    for row in ROWS:
        if row.measure.startswith("time of one seed"):
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
