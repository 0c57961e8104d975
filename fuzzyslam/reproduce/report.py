"""Write reproduce's report: report.md, results.json, commands.sh and the summary figure."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fuzzyslam.reproduce.overrides import set_options
from fuzzyslam.reproduce.plan import Step, evaluations
from fuzzyslam.reproduce.table import (
    Aggregate,
    RowResult,
    SeedResult,
    headline_key,
    run_labels,
)
from fuzzyslam.summary import as_json


@dataclass(frozen=True, kw_only=True)
class RunInfo:
    """results.json's ``info``: the command, suite, configs (with ``--set``, the files
    in OUTDIR that set ``overrides``), seeds, where the steps ran, and the wall time."""

    command: str
    suite: str
    configs: list[str]
    overrides: dict[str, Any]
    seeds: list[int]
    jobs: int
    engine: str
    workers: list[str]
    logs_kept: bool
    steps: int
    version: str
    wall_s: float


@dataclass(frozen=True, kw_only=True)
class StepRecord:
    """A step of the plan as it ran: its command, seconds, stderr, worker and pid."""

    key: str
    command: str
    seconds: float
    stderr: str
    worker: str
    pid: int | None


@dataclass(frozen=True, kw_only=True)
class SeedTime:
    """A seed's summed step time (s)."""

    seed: int
    seconds: float | None


@dataclass(frozen=True, kw_only=True)
class Results:
    """results.json: the run's info, the runs' labels, the table's rows, the seeds'
    times and every step."""

    info: RunInfo
    labels: dict[str, str]
    rows: list[RowResult]
    seeds: list[SeedTime]
    steps: list[StepRecord]


def fmt(v: float | None, digits: int) -> str:
    return "n/a" if v is None else f"{v:.{digits}f}"


def cell(a: Aggregate) -> str:
    """'mean ± std [min, max] unit' of one row over seeds."""
    d = a.row.digits
    if a.mean is None:
        return "n/a"
    unit = f" {a.row.unit}" if a.row.unit and a.row.unit != "x" else a.row.unit
    text = f"{fmt(a.mean, d)}"
    if a.spread is not None:
        v = a.valid
        text += f" ± {fmt(a.spread, d)} [{fmt(min(v), d)}, {fmt(max(v), d)}]"
    return text + unit


def met_text(a: Aggregate) -> str:
    m = a.met
    if m is None:
        return ""
    k, n = m
    return ("yes" if k == n else "no" if k == 0 else "partly") + f" ({k}/{n})"


def results_table(aggs: list[Aggregate], labels: dict[str, str]) -> str:
    """docs/experiment.md's table: paper, target and fuzzyslam side by side."""
    lines = [
        "| phase | measure | paper | target | fuzzyslam | target met (seeds) |",
        "|---|---|---|---|---|---|",
    ]
    for a in aggs:
        r = a.row
        lines.append(
            f"| {r.group} | {r.measure.format(**labels)} | {r.paper} | {r.target} | "
            f"{cell(a)} | {met_text(a)} |"
        )
    return "\n".join(lines)


def seed_table(aggs: list[Aggregate], seeds: list[int], labels: dict[str, str]) -> str:
    head = "| measure | " + " | ".join(f"seed {s}" for s in seeds) + " |"
    lines = [head, "|---|" + "---|" * len(seeds)]
    for a in aggs:
        vals = " | ".join(fmt(v, 0 if a.row.integer else a.row.digits) for v in a.values)
        unit = f" ({a.row.unit})" if a.row.unit else ""
        lines.append(f"| {a.row.group}: {a.row.measure.format(**labels)}{unit} | {vals} |")
    return "\n".join(lines)


def write_commands(path: Path, steps: list[Step], sets: str = "") -> None:
    """The plan as a plain shell script of stage commands (run it from OUTDIR); ``sets``:
    reproduce's ``--set`` options (reproduce/overrides.py ``set_options``), whose config
    files (``set_*.yaml``, in OUTDIR) the commands name."""
    lines = [
        "#!/bin/sh",
        "# Every step of 'fuzzyslam reproduce', as stage commands; run from this directory.",
        "# The same commands with the same seeds write the same files.",
    ]
    if sets:
        lines.append(f"# Configs set_*.yaml (in this directory): the suite's with{sets}.")
    lines.append("set -e")
    seeds = sorted({s.key.split("/")[0] for s in steps})
    for sd in seeds:
        lines.append(f"mkdir -p {sd}")
        lines += [s.command for s in steps if s.key.startswith(f"{sd}/")]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


# summary.png's panels: (log, title, [(run directory, label)])
SUMMARY_PANELS = [
    ("paper", "7 of 15 lamps fail after the freeze",
     [("AB", "lamps only (A, B)"), ("C", "heading fixes (C, paper)"),
      ("C_pose", "pose fixes (beyond)")]),
    ("dark", "every lamp fails after the freeze (beyond the paper)",
     [("dark_none", "lamps only"), ("dark_heading", "heading fixes"),
      ("dark_pose", "pose fixes")]),
]  # fmt: skip


def summary_inputs(seed_dir: str) -> set[str]:
    """The keys of the steps whose files :func:`draw_summary` reads for ``seed_dir`` (the
    logs and the runs of its panels; a plan's steps of them must be done before it)."""
    return {f"{seed_dir}/{k}" for log, _title, runs in SUMMARY_PANELS
            for k in (f"{log}.mcap", *(name for name, _label in runs))}  # fmt: skip


def draw_summary(root: Path, seed_dir: str, out: Path) -> bool:
    """Position error against time for one seed: lamps only (B), heading fixes (C), pose
    fixes, and with every lamp off, with the run and freeze boundaries; False if the files
    are missing. Drawn on a Figure without pyplot (no global figure state: ``reproduce``
    draws it in a thread while the last steps run)."""
    from matplotlib.figure import Figure

    from fuzzyslam.evaluation.evaluate import read_truth
    from fuzzyslam.evaluation.figures import (
        LEFT,
        TIME_LABEL,
        events_bottom,
        events_legend,
        log_start,
        mark_events,
    )
    from fuzzyslam.evaluation.metrics import associate, pose_errors
    from fuzzyslam.evaluation.params import EvalParams
    from fuzzyslam.figsave import (
        PRINT_DPI,
        WIDE_W,
        figure_style,
        fixed_layout,
        save_png,
        series_styles,
    )
    from fuzzyslam.streams.tum import read_tum

    panels = [p for p in SUMMARY_PANELS if (root / seed_dir / f"{p[0]}.mcap").is_file()]
    if not panels:
        return False
    side, top, gap, ax_h = 1.65, 0.3, 0.3, 1.5  # inches: the legends right of the axes
    with figure_style():
        fig = Figure(figsize=(WIDE_W, 1.0), dpi=PRINT_DPI)  # its height set below
        axes = fig.subplots(len(panels), 1, squeeze=False, sharex=True)[:, 0]
        handles: list = []
        for ax, (log, title, runs) in zip(axes, panels, strict=True):
            truth = read_truth(root / seed_dir / f"{log}.mcap", progress=False)
            t0 = log_start(truth)
            curves = []
            for name, label in runs:
                tum = root / seed_dir / name / "trajectory.tum"
                if not tum.is_file():
                    continue
                t, poses = read_tum(tum)
                a = associate(t, poses, truth.t, truth.poses, 0.05, EvalParams().max_gap_s)
                e = pose_errors(a.est, a.truth)
                curves.append((label, a.t - t0, 100.0 * np.hypot(e[:, 0], e[:, 1])))
            # each kind of estimate in its colour, dashes and markers, as in compare.png:
            # the curves coincide until the freeze
            styles = series_styles([c[0] for c in curves], [c[1].size for c in curves])
            for (label, x, y), style in zip(curves, styles, strict=True):
                ax.plot(x, y, lw=1.0, label=label, **style)
            ax.set_yscale("log")
            ax.set_ylabel("position error (cm)")
            ax.set_title(f"{seed_dir}/{log}.mcap: {title}", y=1.0)
            ax.grid(True, which="both", alpha=0.3)
            # right of the axes: over neither the data nor the run labels
            ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False,
                      borderaxespad=0.0)  # fmt: skip
            # run starts (labelled), the freeze, lamp failures: compare.png's markers
            drawn = mark_events([ax], truth, t0)
            if len(drawn) > len(handles):
                handles = drawn
        axes[-1].set_xlabel(TIME_LABEL)
        bottom = events_bottom(len(handles))
        n = len(panels)
        fig.set_size_inches(WIDE_W, top + n * ax_h + (n - 1) * gap + bottom)
        # fixed margins (inches) for the labels and titles, one draw, the blank rest cropped
        fixed_layout(fig, LEFT, side + 0.12, bottom, top, hspace=gap)
        events_legend(fig, axes[-1], handles, bottom)
        save_png(fig, out, PRINT_DPI, tight=True)  # (fuzzyslam/figsave.py)
    return True


def write_report(
    path: Path,
    aggs: list[Aggregate],
    results: list[SeedResult],
    seeds: list[int],
    info: dict[str, Any],
    summary_png: str | None,
    beyond: bool = True,
) -> None:
    """report.md: how it was made, the table, per-seed values and the figures of one seed."""
    labels = run_labels(results[0]) if results else {}
    s0 = f"seed{seeds[0]}"
    lines = [
        "# fuzzyslam reproduce: the paper's experiment",
        "",
        f"`{info.command}`: suite `{info.suite}` (configs {', '.join(info.configs)}), "
        f"seeds {', '.join(map(str, seeds))}, at most {info.jobs} "
        f"step{'s' if info.jobs != 1 else ''} at once, "
        f"{info.wall_s:.0f} s wall time, fuzzyslam {info.version}."
        + (
            " Config keys set in every config (`set_*.yaml`): "
            f"`{set_options(info.overrides).strip()}`."
            if info.overrides
            else ""
        ),
        "Every number below comes from the `metrics.json` of an `evaluate` step "
        "(`seedN/eval_*/`); `commands.sh` lists every step as a stage command.",
        "",
        "## Results",
        "",
        "Mean over seeds ± sample standard deviation [min, max]. Errors are means (or maxima) "
        "of |error| over the runs named, against the simulator's ground truth. "
        "Phase A is {A}, B and C are {after} of the same log (C re-run with heading "
        "fixes from the FGM frozen at the end of run {freeze}); D is its own log with a "
        "10-degree bump in every run, localised with heading fixes from the phase-A map from "
        "its start.".format(**labels)
        if labels
        else "",
        "",
        results_table(aggs, labels),
        "",
        "Notes: the paper gives phase D's errors as 25 cm (x), 18 cm (y) and 15 deg, the "
        "largest in its Fig. 3; the heading error right after a bump is the bump itself "
        "(10 deg, unseen by odometry) until the first fixes, so the 3-degree target is read "
        "on the mean. The Hough accuracy is the error of the accepted heading fixes against "
        "the true heading. Lamp duplicates are estimated lamps left unmatched within "
        "the matching distance of a true lamp after a one-to-one assignment. "
        "The odometry self-calibration rows compare the factors of the map (the lamps-only "
        "run's at the freeze time, which phases C and D start from) and of the C and D runs "
        "with the simulator's true wheels (the config's `robot.left_scale`, `right_scale`, "
        "`base_scale`), the errors in the estimate's own sigmas; n/a when the runs do not "
        "calibrate (`slam.calibrate` off: `reproduce --set slam.calibrate=false`; the "
        "shipped configs calibrate). "
        "The real-time factors of the Cost rows are measured while reproduce's jobs share the "
        "machine's cores; the isolated figures come from the benchmarks.",
        "",
        "## Per seed",
        "",
        seed_table(aggs, seeds, labels),
        "",
        f"## Figures ({s0})",
        "",
    ]
    if summary_png:
        lines += [
            "Position error against time: phases A-C, and every lamp off after the freeze.",
            "",
            f"![position errors]({summary_png})",
            "",
        ]
    figs = [
        ("Fig. 1: the FGM with the estimated and odometry paths and the lamps (phase C)",
         f"{s0}/eval_C/fig1_paths.png"),
        ("Fig. 2: corridor segments and an FLM with their Hough planes", f"{s0}/fgm/hough.png"),
        ("The frozen FGM with the corridor references", f"{s0}/fgm/fgm.png"),
        ("Fig. 3: x, y and heading errors, lamps only (phases A and B)",
         f"{s0}/eval_AB/fig3_errors.png"),
        ("Fig. 3: x, y and heading errors, heading fixes (phases A and C)",
         f"{s0}/eval_C/fig3_errors.png"),
        ("Fig. 3: x, y and heading errors with bumps (phase D)", f"{s0}/eval_D/fig3_errors.png"),
        ("Fig. 4: per-lamp errors (phase C)", f"{s0}/eval_C/fig4_lamps.png"),
        ("Fig. 4: per-lamp errors with bumps (phase D)", f"{s0}/eval_D/fig4_lamps.png"),
        ("Every lamp off after the freeze, pose fixes", f"{s0}/eval_dark_pose/fig3_errors.png"),
        ("Change detections with people and boxes in the corridors (pose fixes)",
         f"{s0}/people_pose/changes.png"),
    ]  # fmt: skip
    root = path.parent
    for title, rel in figs:
        if (root / rel).is_file():
            lines += [f"### {title}", "", f"![{title}]({rel})", ""]
    lines += ["## Every evaluation", ""]
    for name, (_log, _est, _map, label) in evaluations(beyond).items():
        links = ", ".join(f"[seed {s}](seed{s}/eval_{name}/report.md)" for s in seeds)
        lines.append(f"- {label}: {links}")
    lines.append("")
    path.write_text("\n".join(lines), encoding="utf-8")


def write_results(
    path: Path,
    aggs: list[Aggregate],
    results: list[SeedResult],
    info: RunInfo,
    steps: list[StepRecord],
) -> None:
    """results.json: the table (values per seed, mean, std, min, max, target met, the
    headline key with its unit), info, and every step (command, seconds, its stderr)."""
    labels = run_labels(results[0]) if results else {}
    data = Results(
        info=info,
        labels=labels,
        rows=[  # each row with its key in the headline JSON (stage.py)
            a.result(headline_key(a.row, labels) if labels else None) for a in aggs
        ],
        seeds=[SeedTime(seed=r.seed, seconds=r.seconds) for r in map(SeedResult.of, results)],
        steps=steps,
    )
    path.write_text(json.dumps(as_json(data), indent=2, sort_keys=True), encoding="utf-8")
