"""The dark lap on a one-lap map (docs/models.md sec. 9): the quick world with every lamp
off in run 2 and three 10-degree bumps (tests/test_bump_dark_sim.py's scenario), on
seed 9. Its map once had no corridor reference for the half of the start corridor that
run 1 drove last (the weaving path's segments, sec. 8); run 2 starts there: 1.7 m from
the left corridor's region, the heading aid offered that corridor alone (a "junction" of
one direction), three rings saw the start corridor's walls 90 deg off its comb, and the
streak rule recovered a correct heading by 90 deg (the position variance inflated to
12 m^2, the estimate 10 m off). The map now covers the start corridor to 2.2 m from the
bottom-left corner, but at that corner (1.3 m from the left corridor's region, 2.2 m
from the start corridor's) the aid still offers the left corridor alone, and the old
rule recovers by 88 deg there (145.75 s). Such rings are no bump evidence now
(fixes/bump_recovery.py ``unsure_junction``). ``simulate | run | map | run --map --fix
heading`` through the CLI, against the simulator's truth; and the health report's
``position_unresolved`` on the run as it was."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import shared_dir
from test_bump_dark_sim import BUMPS
from test_fixes_sim import ALL_LAMPS, chain, errors, invoke, run_interval

from fuzzyslam.se2 import wrap_angle
from fuzzyslam.streams.logmeta import read_scenario
from fuzzyslam.streams.reader import LogReader

pytestmark = pytest.mark.slow  # simulated log, lamps-only run, map and two fixed runs


@pytest.fixture(scope="session")
def one_lap(tmp_path_factory):
    def build(tmp: Path) -> None:
        scenario = {"lamp_failures": [{"run": 2, "lamps": ALL_LAMPS}], "bumps": BUMPS}
        log, fgm = chain(tmp, {"scenario": scenario}, 9)
        out = invoke(["run", log, "--map", fgm, "--fix", "heading", "-o", tmp / "fixed",
                      "--config", tmp / "scenario.yaml"])  # fmt: skip
        (tmp / "summary.json").write_text(json.dumps(out))

    tmp = shared_dir(tmp_path_factory, "dark-one-lap", build)
    return tmp / "log.mcap", tmp


def test_dark_lap_on_a_one_lap_map_holds_the_pose(one_lap):
    """The map covers the half of the start corridor run 1 drove last (a region on its
    line y = 0 reaches x < 3 m: the weaving path's segments, docs/models.md sec. 8; it
    once stopped at x = 6.5 m). Run 2 holds its pose: the position error stays below
    25 cm (it was 10 m before the one-direction rule), the heading within 2 deg of the
    truth except in the 4 s after each bump, every recovery turns the heading by 5-15
    deg (a bump's 10, none by 90), one after each bump; and the health report finds no
    trouble."""
    log, tmp = one_lap
    refs = yaml.safe_load((tmp / "fgm" / "references.yaml").read_text())["references"]
    on_start_line = [r for r in refs if abs(np.mean(np.array(r["region"])[:, 1])) < 0.5]
    assert any(np.array(r["region"])[:, 0].min() < 3.0 for r in on_start_line), refs
    t, err = errors(log, tmp / "fixed")
    run2 = t >= run_interval(log, 2)[0]
    e = np.hypot(err[:, 0], err[:, 1])
    assert e[run2].max() < 0.25, e[run2].max()
    bumps = [e.t for e in read_scenario(LogReader(log)).events if e.kind == "bump"]
    away = run2.copy()
    for b in bumps:
        away &= ~((t >= b) & (t <= b + 4.0))
    assert np.degrees(np.abs(err[away, 2])).max() < 2.0
    with open(tmp / "fixed" / "heading_fixes.csv", newline="") as fh:
        rec = [r for r in csv.DictReader(fh) if r["reason"] == "recovered"]
    turn = np.degrees(
        np.abs(wrap_angle(np.array([float(r["measured"]) - float(r["predicted"]) for r in rec])))
    )
    assert np.all((turn > 5.0) & (turn < 15.0)), turn
    since = np.array([float(r["t"]) for r in rec])[:, None] - np.array(bumps)[None, :]
    assert np.all(np.any((since >= 0) & (since <= 4.0), axis=0)), since  # each bump
    summary = json.loads((tmp / "summary.json").read_text())
    assert not summary["filter_health"]["diverged"], summary["filter_health"]
    aid = summary["aids"]["HeadingFixAid"]
    assert aid["position_unresolved_at"] is None and aid["position_sigma_max_m"] < 0.3


def test_health_flags_the_lost_pose_of_the_old_rule(one_lap, tmp_path):
    """With one-direction junction rings counted as bump evidence again (the old rule,
    patched back in), the same run loses its pose, and its summary says so: reason
    position_unresolved, from the false recovery's ring on, while the error against
    the truth is metres."""
    import fuzzyslam.fixes.bump_recovery as br

    log, tmp = one_lap
    mp = pytest.MonkeyPatch()
    mp.setattr(br, "one_direction", lambda refs: False)
    try:
        out = invoke(["run", log, "--map", tmp / "fgm", "--fix", "heading", "-o",
                      tmp_path / "old", "--config", tmp / "scenario.yaml"])  # fmt: skip
    finally:
        mp.undo()
    health = out["filter_health"]
    assert health["diverged"] and "position_unresolved" in health["reasons"], health
    t, err = errors(log, tmp_path / "old")
    e = np.hypot(err[:, 0], err[:, 1])
    lost = t >= health["diverged_at"]
    assert e[~lost].max() < 0.1 and e[lost].max() > 1.0
    with open(tmp_path / "old" / "heading_fixes.csv", newline="") as fh:
        first = next(float(r["t"]) for r in csv.DictReader(fh) if r["reason"] == "recovered")
    assert health["diverged_at"] == first  # the recovery inflated the position
