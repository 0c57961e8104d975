"""Report files: metrics.json (every figure) and report.md (a short table and the PNGs)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from fuzzyslam.fileio import atomic_path


def _clean(obj: Any) -> Any:
    """JSON-ready copy: NaN/inf become null (strict JSON), tuples lists."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if hasattr(obj, "item"):
        return _clean(obj.item())
    return obj


def write_metrics(path: Path, metrics: dict[str, Any]) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(
            json.dumps(_clean(metrics), indent=2, sort_keys=True, allow_nan=False) + "\n",
            encoding="utf-8",
        )


def _f(v: Any, k: float = 1.0, nd: int = 1) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v * k:.{nd}f}"


def phase_table(metrics: dict[str, Any]) -> str:
    """Markdown table: one row per phase / run, errors in cm and degrees."""
    head = (
        "| phase | runs | samples | mean pos. err (cm) | RMSE x / y (cm) | max pos. err (cm) "
        "| heading mean / max (deg) | APE RMSE raw / aligned (cm) | RPE (cm/m) | NEES (band) |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n"
    )
    rows = []
    for name, b in metrics["phases"].items():
        if "position_m" not in b:
            continue
        nees = b.get("nees")
        nees_s = (
            f"{_f(nees['mean'], nd=2)} ({_f(nees['band_lo'], nd=2)}-{_f(nees['band_hi'], nd=2)})"
            if nees and nees["n"]
            else "-"
        )
        rows.append(
            f"| {name} | {','.join(map(str, b['runs'])) or '-'} | {b['samples']} "
            f"| {_f(b['position_m']['mean'], 100)} "
            f"| {_f(b['x_m']['rmse'], 100)} / {_f(b['y_m']['rmse'], 100)} "
            f"| {_f(b['position_m']['max'], 100)} "
            f"| {_f(b['heading_deg']['mean'], nd=2)} / {_f(b['heading_deg']['max'], nd=2)} "
            f"| {_f(b['ape_m']['raw']['rmse'], 100)} / {_f(b['ape_m']['aligned']['rmse'], 100)} "
            f"| {_f(b['rpe']['trans_m_per_m']['mean'], 100, 2)} | {nees_s} |"
        )
    return head + "\n".join(rows) + "\n"


def comparison_table(rows: list[dict[str, Any]]) -> str:
    """Markdown table of ``evaluate --compare``: per phase (A, after, overall; the per-run
    blocks stay in metrics.json), one row per estimate."""
    head = (
        "| phase | estimate | mean pos. err (cm) | max pos. err (cm) "
        "| heading mean / max (deg) | lamps duplicated |\n"
        "|---|---|---|---|---|---|\n"
    )
    names = [n for n in rows[0]["phases"] if not n.startswith("run")]
    out = []
    for name in names:
        for r in rows:
            b = r["phases"].get(name)
            if b is None:
                continue
            dup = "-" if r["lamps_duplicated"] is None else str(r["lamps_duplicated"])
            out.append(
                f"| {name} | {r['label']} | {_f(b['position_mean_m'], 100, 2)} "
                f"| {_f(b['position_max_m'], 100, 2)} "
                f"| {_f(b['heading_mean_deg'], nd=2)} / {_f(b['heading_max_deg'], nd=2)} | {dup} |"
            )
    return head + "\n".join(out) + "\n"


def _truth_lines(metrics: dict[str, Any]) -> list[str]:
    """The report's lines on the truth itself: its stray lines dropped, the alignment."""
    out = []
    if "truth_lines_dropped" in metrics:
        out.append(
            f"- truth lines dropped as stray (odometry glitch gate): "
            f"{metrics['truth_lines_dropped']}"
        )
    al = metrics.get("aligned_to_truth")
    if al:
        out.append(
            f"- estimate aligned to the truth by one rigid motion: {_f(al['tx_m'], nd=3)} m, "
            f"{_f(al['ty_m'], nd=3)} m, {_f(al['theta_deg'], nd=2)} deg "
            "(NEES in the estimate's own frame, anchored at its first pose)"
        )
    return out


def write_report(path: Path, metrics: dict[str, Any], figs: dict[str, str]) -> None:
    """report.md: the headline, the phase table, lamps, fixes, consistency and the figures."""
    lines = [
        f"# Evaluation: {metrics['label']}",
        "",
        f"- truth: `{metrics['truth']}`",
        f"- estimate: `{metrics['estimate']}`",
        f"- compared samples: {metrics['samples']} over "
        f"{metrics['span_s'][0]:.1f}-{metrics['span_s'][1]:.1f} s "
        f"(truth interpolated at estimate times between truth samples at most "
        f"{metrics['params']['max_gap_s']} s apart, or within "
        f"{metrics['params']['max_dt_s']} s of one)",
        *_truth_lines(metrics),
        *(f"- **warning**: {w}" for w in metrics.get("warnings", [])),
        "",
        "## Pose errors by phase",
        "",
        "Phase `A` = runs 1..freeze run (map building), `after` = later runs; errors are "
        "estimate minus truth in the truth's frame"
        + (
            " (the estimate moved by one rigid motion fitted on the whole log, `aligned_to_truth`)"
            if "aligned_to_truth" in metrics
            else ""
        )
        + ". APE raw = no fit of its own (`evo_ape tum truth.tum trajectory.tum` overall: "
        "truth.tum is written in the estimate's frame); APE aligned = after a rigid Umeyama "
        "fit of the positions (as `evo_ape --align`; fitted within each phase). RPE per metre "
        "of true travel.",
        "",
        phase_table(metrics),
    ]
    if "odometry" in metrics:
        od = metrics["odometry"]
        lines += [
            f"Odometry only: mean position error {_f(od['position_m']['mean'], 100)} cm, "
            f"max {_f(od['position_m']['max'], 100)} cm, mean heading error "
            f"{_f(od['heading_deg']['mean'], nd=2)} deg.",
            "",
        ]
    if "lamps" in metrics:
        lm = metrics["lamps"]
        lines += [
            "## Lamps",
            "",
            f"{lm['estimated']} estimated, {lm['true']} true: {lm['matched']} matched "
            f"(within {_f(lm['max_dist_m'], 100, 0)} cm, one to one), mean error "
            f"{_f(lm['error_m']['mean'], 100)} cm, max {_f(lm['error_m']['max'], 100)} cm; "
            f"**{lm['duplicates']} duplicated**, {lm['missed']} missed, "
            f"{lm['spurious']} spurious.",
            "",
        ]
    if metrics.get("comparison"):
        lines += ["## Side by side", "", comparison_table(metrics["comparison"])]
    ov = metrics["phases"]["overall"]
    if "heading_fix" in ov:
        lines += [
            "## Hough heading fixes",
            "",
            "| phase | attempted | accepted | error mean (deg) | error std (deg) |",
            "|---|---|---|---|---|",
        ]
        for name, b in metrics["phases"].items():
            hf = b.get("heading_fix")
            if hf and hf["attempted"]:
                lines.append(
                    f"| {name} | {hf['attempted']} | {hf['accepted']} "
                    f"| {_f(hf['error_deg']['mean'], nd=2)} | {_f(hf['error_deg']['std'], nd=2)} |"
                )
        lines.append("")
    if ov.get("nis"):
        lines += [
            "## Innovation consistency (accepted updates)",
            "",
            "| kind | n | mean NIS | 95 % band of the mean |",
            "|---|---|---|---|",
        ]
        for k, c in ov["nis"].items():
            lines.append(
                f"| {k} | {c['n']} | {_f(c['mean'], nd=2)} "
                f"| {_f(c['band_lo'], nd=2)}-{_f(c['band_hi'], nd=2)} |"
            )
        lines.append("")
    captions = {
        "fig1": "Fig. 1: true, estimated and odometry-only paths, lamps and walls",
        "fig3": "Fig. 3: x, y, heading errors against time",
        "fig4": "Fig. 4: per-lamp position error",
        "consistency": "NEES and NIS against time",
        "compare": "position errors of the compared estimates against time",
    }
    lines += ["## Figures", ""]
    for key, name in figs.items():
        lines += [f"![{captions.get(key, key)}]({name})", ""]
    lines += ["Every number above, and more, is in `metrics.json`.", ""]
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines), encoding="utf-8")
