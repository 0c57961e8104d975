"""docs/experiment.md's table: the paper's figure, our target and fuzzyslam's, over seeds (pure).

A seed's results are a :class:`SeedResult`: the metrics.json of each evaluation of the
plan (names of :data:`fuzzyslam.reproduce.plan.EVALUATIONS`), the summaries of its runs
and maps, the summed step times. Each :class:`Row` extracts one number per seed
(:func:`metric`: a key the table reads that the results lack is an error,
:class:`MissingMetric`, never a blank cell; a blank is a metric written as null or not
finite, or an evaluation or run outside the plan); :func:`aggregate` gives its mean and
spread and whether the target is met. The odometry self-calibration's rows compare the
runs' and the map's factors (their summaries' ``calibration``) with the simulator's true
wheels (:attr:`SeedResult.calibration_truth`, from the configs), n/a when the runs do not
calibrate (``slam.calibrate`` off).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from fuzzyslam.slam.calibration import NAMES, errors_in_sigma


class MissingMetric(KeyError):
    """A metric the table reads is not in the results (a renamed or dropped key)."""


@dataclass(frozen=True)
class SeedResult:
    """One seed's results (reproduce/stage.py ``seed_result``).

    ``eval``: metrics.json of each evaluation of the plan; ``run``, ``map``: the JSON
    summaries of its runs and maps by step name; ``seconds``: its steps' summed times;
    ``calibration_truth``: per log of the plan (paper, bumps) whose config calibrates
    the odometry (``slam.calibrate``), the simulator's true wheel factors (s_L, s_R,
    s_B; ``slam.calibration.true_factors``); a log without an entry does not calibrate."""

    seed: int
    eval: dict[str, dict[str, Any]] = field(default_factory=dict)
    run: dict[str, dict[str, Any]] = field(default_factory=dict)
    map: dict[str, dict[str, Any]] = field(default_factory=dict)
    seconds: float | None = None
    calibration_truth: dict[str, list[float]] = field(default_factory=dict)

    @classmethod
    def of(cls, r: SeedResult | dict[str, Any]) -> SeedResult:
        """``r`` itself, or the SeedResult of its dict form (``{seed, eval, run, map,
        seconds, calibration_truth}``, parts left out empty)."""
        if isinstance(r, SeedResult):
            return r
        parts = (r.get("eval", {}), r.get("run", {}), r.get("map", {}))
        return cls(r.get("seed", 0), *parts, r.get("seconds"), r.get("calibration_truth", {}))


def metric(tree: Any, *path: str) -> Any:
    """``tree[p0][p1]...``; None when a value on the way is null (a metric a run could not
    give). MissingMetric when a key is missing: the results do not have the shape the
    table reads."""
    d = tree
    for i, p in enumerate(path):
        if d is None:
            return None
        if not isinstance(d, dict) or p not in d:
            raise MissingMetric(f"no {'.'.join(path[: i + 1])} in the results")
        d = d[p]
    return d


def _num(v: Any, scale: float = 1.0) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        return None
    return float(v) * scale


def phase_stat(ev: str, phase: str, *path: str, scale: float = 1.0):
    """Extractor of ``eval[ev].phases[phase][path...]`` (``phase``: 'A', 'after', 'overall')."""

    def get(r: SeedResult) -> float | None:
        m = r.eval.get(ev)  # None: an evaluation outside the plan (--paper-only)
        return None if m is None else _num(metric(m, "phases", phase, *path), scale)

    return get


def _lamp_snapshot(r: SeedResult, ev: str, which: str) -> dict | None:
    """Lamp matching at the end of the freeze run ('freeze') or of the last run ('last')."""
    m = r.eval.get(ev)
    by_run = metric(m, "lamps_by_run") if m is not None else None
    if not by_run:  # outside the plan, or no lamp at the end of any run
        return None
    if which == "freeze":
        return metric(by_run, f"run{metric(m, 'freeze_run')}")
    return by_run[max(by_run, key=lambda k: int(k[3:]))]


def lamp_error(ev: str, which: str = "freeze", scale: float = 100.0):
    def get(r: SeedResult) -> float | None:
        return _num(metric(_lamp_snapshot(r, ev, which), "error_m", "mean"), scale)

    return get


def duplicates(ev: str, which: str = "last"):
    def get(r: SeedResult) -> float | None:
        return _num(metric(_lamp_snapshot(r, ev, which), "duplicates"))

    return get


def ratio(num: Callable, den: Callable):
    def get(r: SeedResult) -> float | None:
        a, b = num(r), den(r)
        return None if a is None or b is None or b <= 0 else a / b

    return get


def run_value(run: str, key: str):
    def get(r: SeedResult) -> float | None:
        s = r.run.get(run)  # None: a run outside the plan
        return None if s is None else _num(metric(s, key))

    return get


def reference_error(which: str):
    """Largest |reference angle - true corridor axis| (deg) of a map, or their mean."""

    def get(r: SeedResult) -> float | None:
        m = r.map.get("fgm")  # None: no map in the results
        truth = (metric(m, "reference_truth") if m is not None else None) or []
        errs = [_num(metric(e, "error_deg")) for e in truth]
        errs = [abs(e) for e in errs if e is not None]
        if not errs:
            return None
        return max(errs) if which == "max" else sum(errs) / len(errs)

    return get


def seed_seconds(r: SeedResult) -> float | None:
    return _num(r.seconds)


def change_score(key: str):
    def get(r: SeedResult) -> float | None:
        m = r.eval.get("people_pose")
        return None if m is None else _num(metric(m, "change_detection", key))

    return get


# The calibration rows' estimates: step name -> (summaries it is in, the log it ran on)
CALIBRATED = {"fgm": ("map", "paper"), "C": ("run", "paper"), "D": ("run", "bumps")}


def calibration(est: str, what: str, i: int = 0):
    """Extractor of the odometry self-calibration of estimate ``est`` (:data:`CALIBRATED`:
    the map's, at the freeze time, or a run's, at its end) against the simulator's true
    wheels: ``what`` 'truth', 'factor' (factor ``i`` of s_L, s_R, s_B), 'error' (its
    error in sigmas, ``slam.calibration.errors_in_sigma``) or 'worst' (the largest
    magnitude of the three errors). None when the log's runs do not calibrate, for an
    estimate outside the plan, and for a model other than the wheels' (no true factors);
    MissingMetric when they calibrate and the summary has no ``calibration``."""
    kind, log = CALIBRATED[est]

    def get(r: SeedResult) -> float | None:
        truth = r.calibration_truth.get(log)
        s = (r.map if kind == "map" else r.run).get(est)
        if truth is None or s is None:
            return None
        if what == "truth":
            return _num(truth[i])
        c = metric(s, "calibration")
        if c is None or tuple(metric(c, "names")) != NAMES["wheels"]:
            return None
        if what == "factor":
            return _num(metric(c, "factors")[i])
        err = errors_in_sigma(metric(c, "factors"), metric(c, "sigma"), truth)
        return _num(err[i] if what == "error" else max(abs(e) for e in err))

    return get


@dataclass(frozen=True)
class Row:
    """One line of the table: what is measured, the paper's figure, the target, how to get it."""

    group: str
    measure: str
    paper: str
    target: str
    get: Callable[[SeedResult], float | None]
    unit: str = ""
    ok: Callable[[float], bool] | None = None
    digits: int = 2
    integer: bool = False  # a count: per-seed values are shown without decimals


def _le(limit: float) -> Callable[[float], bool]:
    return lambda v: v <= limit


def _within(limit: float) -> Callable[[float], bool]:
    return lambda v: abs(v) <= limit


def _eq0(v: float) -> bool:
    return v == 0


CM = 100.0
A_POS = phase_stat("AB", "A", "position_m", "mean", scale=CM)
CAL = "Odometry self-calibration"
WHEELS = (("left wheel scale", "s_L"), ("right wheel scale", "s_R"), ("wheel-base scale", "s_B"))

ROWS: tuple[Row, ...] = (
    Row("A. SLAM and map building", "mean position error, {A}", "< 5 cm", "<= 3 cm",
        A_POS, "cm", _le(3.0)),
    Row("A. SLAM and map building", "mean lamp error, end of run {freeze}", "< 5 cm", "<= 3 cm",
        lamp_error("AB", "freeze"), "cm", _le(3.0)),
    Row("A. SLAM and map building", "NEES mean (3 dof; 3 = consistent)", "-", "-",
        phase_stat("AB", "A", "nees", "mean"), ""),
    Row("A. SLAM and map building", "duplicate lamps, end of run {freeze}", "-", "0",
        duplicates("AB", "freeze"), "", _eq0, 1, True),
    Row("A. SLAM and map building", "corridor reference angle error, mean abs.",
        "1 deg", "<= 0.3 deg", reference_error("mean"), "deg", _le(0.3)),
    Row("A. SLAM and map building", "corridor reference angle error, largest abs.", "-",
        "<= 0.3 deg", reference_error("max"), "deg", _le(0.3)),
    Row("B. lamp failure, no help", "mean position error, {after}", "diverges", "-",
        phase_stat("AB", "after", "position_m", "mean", scale=CM), "cm"),
    Row("B. lamp failure, no help", "max position error, {after}", "diverges", "-",
        phase_stat("AB", "after", "position_m", "max", scale=CM), "cm"),
    Row("B. lamp failure, no help", "duplicate lamps, end of run {last}", "created", "0",
        duplicates("AB"), "", _eq0, 1, True),
    Row("C. lamp failure with Hough", "mean position error, {after}", "about 2x A",
        "<= 1.5x A", phase_stat("C", "after", "position_m", "mean", scale=CM), "cm"),
    Row("C. lamp failure with Hough", "ratio to phase A", "about 2", "<= 1.5",
        ratio(phase_stat("C", "after", "position_m", "mean"), phase_stat("C", "A", "position_m",
              "mean")), "x", _le(1.5)),
    Row("C. lamp failure with Hough", "max position error, {after}", "-", "-",
        phase_stat("C", "after", "position_m", "max", scale=CM), "cm"),
    Row("C. lamp failure with Hough", "duplicate lamps, end of run {last}", "-", "0",
        duplicates("C"), "", _eq0, 1, True),
    Row("Hough accuracy", "heading-fix error, mean abs., {after}", "1.0 deg", "<= 0.5 deg",
        phase_stat("C", "after", "heading_fix", "error_deg", "mean"), "deg", _le(0.5)),
    Row("Hough accuracy", "heading-fix error std, {after}", "0.66 deg", "<= 0.5 deg",
        phase_stat("C", "after", "heading_fix", "error_deg", "std"), "deg", _le(0.5)),
    Row("D. bumps (heading fixes)", "max x error, {all}", "25 cm", "<= 10 cm",
        phase_stat("D", "overall", "x_m", "max", scale=CM), "cm", _le(10.0)),
    Row("D. bumps (heading fixes)", "max y error, {all}", "18 cm", "<= 10 cm",
        phase_stat("D", "overall", "y_m", "max", scale=CM), "cm", _le(10.0)),
    Row("D. bumps (heading fixes)", "mean heading error", "-", "<= 3 deg",
        phase_stat("D", "overall", "heading_deg", "mean"), "deg", _le(3.0)),
    Row("D. bumps (heading fixes)", "max heading error (the unseen bump itself)", "15 deg", "-",
        phase_stat("D", "overall", "heading_deg", "max"), "deg"),
    Row("D. bumps (heading fixes)", "duplicate lamps, end of run {last}", "-", "0",
        duplicates("D"), "", _eq0, 1, True),
    Row("Beyond: all lamps off", "mean position error, {after}, no fixes", "not attempted",
        "-", phase_stat("dark_none", "after", "position_m", "mean", scale=CM), "cm"),
    Row("Beyond: all lamps off", "mean position error, {after}, heading fixes",
        "not attempted", "-",
        phase_stat("dark_heading", "after", "position_m", "mean", scale=CM), "cm"),
    Row("Beyond: all lamps off", "mean position error, {after}, pose fixes", "not attempted",
        "<= 15 cm", phase_stat("dark_pose", "after", "position_m", "mean", scale=CM), "cm",
        _le(15.0)),
    Row("Beyond: all lamps off", "max position error, {after}, pose fixes", "not attempted",
        "<= 15 cm", phase_stat("dark_pose", "after", "position_m", "max", scale=CM), "cm",
        _le(15.0)),
    Row("Beyond: people and boxes", "mean position error, {after}, pose fixes", "-",
        "as without them",
        phase_stat("people_pose", "after", "position_m", "mean", scale=CM), "cm"),
    Row("Beyond: people and boxes", "same log without them (phase C, pose fixes)", "-", "-",
        phase_stat("C_pose", "after", "position_m", "mean", scale=CM), "cm"),
    Row("Beyond: people and boxes", "change detection precision", "-", "-",
        change_score("precision"), ""),
    Row("Beyond: people and boxes", "change detection recall", "-", "-",
        change_score("recall"), ""),
    *(row for i, (name, sym) in enumerate(WHEELS) for row in (
        Row(CAL, f"{name} {sym}, the simulator's truth", "-", "-",
            calibration("fgm", "truth", i), "", None, 5),
        Row(CAL, f"{name} {sym}, the map's at the end of run {{freeze}}", "-", "-",
            calibration("fgm", "factor", i), "", None, 5),
        Row(CAL, f"{sym} error, the map's at the end of run {{freeze}}", "-",
            "within 2 sigma", calibration("fgm", "error", i), "sigma", _within(2.0)),
    )),
    Row(CAL, "largest abs. error of s_L, s_R, s_B, the map's at the end of run {freeze}", "-",
        "<= 2 sigma", calibration("fgm", "worst"), "sigma", _le(2.0)),
    Row(CAL, "largest abs. error of s_L, s_R, s_B, end of phase C (heading fixes)", "-",
        "<= 2 sigma", calibration("C", "worst"), "sigma", _le(2.0)),
    Row(CAL, "largest abs. error of s_L, s_R, s_B, end of phase D (bumps)", "-", "<= 2 sigma",
        calibration("D", "worst"), "sigma", _le(2.0)),
    # Under reproduce's own load (its jobs share the machine's cores): the isolated figures
    # come from benchmarks/bench_run.py and bench_fixes.py.
    Row("Cost", "run real-time factor, lamps only (A+B), under load", "-", "-",
        run_value("AB", "real_time_factor"), "x", None, 0),
    Row("Cost", "run real-time factor, heading fixes (C), under load", "-", "-",
        run_value("C", "real_time_factor"), "x", None, 0),
    Row("Cost", "run real-time factor, pose fixes (C), under load", "-", "-",
        run_value("C_pose", "real_time_factor"), "x", None, 0),
    Row("Cost", "time of one seed's steps, summed (one core each)", "-", "-", seed_seconds, "s",
        None, 0),
)  # fmt: skip


@dataclass(frozen=True)
class Aggregate:
    """A row's values over seeds (None where a seed could not give it)."""

    row: Row
    values: tuple[float | None, ...]

    @property
    def valid(self) -> list[float]:
        return [v for v in self.values if v is not None]

    @property
    def mean(self) -> float | None:
        v = self.valid
        return sum(v) / len(v) if v else None

    @property
    def spread(self) -> float | None:
        """Sample standard deviation over seeds (None for fewer than two)."""
        v = self.valid
        if len(v) < 2:
            return None
        m = sum(v) / len(v)
        return math.sqrt(sum((x - m) ** 2 for x in v) / (len(v) - 1))

    @property
    def met(self) -> tuple[int, int] | None:
        """(seeds meeting the target, seeds measured), or None for rows without a target."""
        if self.row.ok is None or not self.valid:
            return None
        return sum(bool(self.row.ok(v)) for v in self.valid), len(self.valid)

    def result(self, key: str | None) -> RowResult:
        """The row as results.json holds it, with its ``key`` in the headline JSON.

        Parameters
        ----------
        key : str or None
            :func:`headline_key` of the row (None without run labels).

        Returns
        -------
        RowResult
        """
        v = self.valid
        return RowResult(
            group=self.row.group,
            measure=self.row.measure,
            unit=self.row.unit,
            paper=self.row.paper,
            target=self.row.target,
            values=list(self.values),
            mean=self.mean,
            std=self.spread,
            min=min(v) if v else None,
            max=max(v) if v else None,
            met=list(self.met) if self.met is not None else None,
            key=key,
        )


@dataclass(frozen=True, kw_only=True)
class RowResult:
    """A row of the table in results.json: the paper's figure, the target, the values
    per seed and their mean, std, min, max, seeds meeting the target, headline key."""

    group: str
    measure: str
    unit: str
    paper: Any
    target: Any
    values: list[float | None]
    mean: float | None
    std: float | None
    min: float | None
    max: float | None
    met: list[int] | None
    key: str | None


HEADLINE_UNITS = ("cm", "deg", "m", "s", "x", "sigma", "count", "ratio")


def unit_suffix(row: Row) -> str:
    """The unit a headline key ends with: the row's unit (cm, deg, m, s; x for a ratio shown
    as a multiple; sigma for an error in the estimate's own standard deviations), else
    ``count`` for counts and ``ratio`` for other dimensionless values (NEES, precision,
    recall, the calibration factors)."""
    unit = row.unit or ("count" if row.integer else "ratio")
    if unit not in HEADLINE_UNITS:
        raise ValueError(f"row {row.measure!r}: unit {unit!r} is not one of {HEADLINE_UNITS}")
    return unit


def headline_key(row: Row, labels: dict[str, str]) -> str:
    """The row's key in reproduce's headline JSON and results.json's ``key``:
    ``"<group>: <measure>_<unit>"`` (measure placeholders filled from ``labels``)."""
    return f"{row.group}: {row.measure}".format(**labels) + f"_{unit_suffix(row)}"


def aggregate(
    results: list[SeedResult] | list[dict[str, Any]], rows: tuple[Row, ...] = ROWS
) -> list[Aggregate]:
    """Each row's value for each seed's results, in seed order (MissingMetric: a metric
    the row reads is not in a seed's results)."""
    typed = [SeedResult.of(r) for r in results]
    return [Aggregate(row, tuple(row.get(r) for r in typed)) for row in rows]


def run_labels(result: SeedResult | dict[str, Any]) -> dict[str, str]:
    """Run ranges that fill the measures' placeholders: {A}, {after}, {all}, {freeze}, {last}."""
    ab = SeedResult.of(result).eval.get("AB")
    ph = metric(ab, "phases") if ab is not None else {}

    def span(runs: list[int] | None) -> str:
        if not runs:
            return "runs ?"
        return f"run {runs[0]}" if len(runs) == 1 else f"runs {runs[0]}-{runs[-1]}"

    a = metric(ph, "A", "runs") if "A" in ph else None  # a phase with no run: absent
    after = metric(ph, "after", "runs") if "after" in ph else None
    every = sorted({*(a or []), *(after or [])})
    freeze = metric(ab, "freeze_run") if ab is not None else None
    return {
        "A": span(a),
        "after": span(after),
        "all": span(every),
        "freeze": str(freeze) if freeze is not None else "?",
        "last": str(every[-1]) if every else "?",
    }
