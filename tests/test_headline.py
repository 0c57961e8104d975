"""The reproduce headline JSON carries its units (issue 17): every key ends with one."""

from __future__ import annotations

import json

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
