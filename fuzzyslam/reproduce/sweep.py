"""``fuzzyslam sweep``: a grid of config values x seeds through simulate, run, evaluate.

Each grid point is a config file ``OUTDIR/gI.yaml`` that ``extends`` the base config and
sets the swept keys; each (grid point, seed) is the chain::

    simulate gI.yaml --seed S -> gI/seedS/log.mcap -> run -> gI/seedS/est
                                                    -> evaluate -> gI/seedS/eval

run by the same engine as ``reproduce`` (local pool or ``--scheduler``), in OUTDIR itself
so that a sweep killed halfway goes on: every finished step leaves a record
``OUTDIR/.sweep/<step>.json`` with a content hash of its command, the config files it
names, the fuzzyslam version and its dependencies' hashes (a chain, so a changed config
reaches every step after it). A step whose hash is unchanged and whose output exists is
skipped and counted. The table (``sweep.md``, ``sweep.json``) gives, per grid point, the
mean, sample standard deviation, min and max over seeds of the evaluation's errors.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
import os
import shutil
from pathlib import Path
from typing import Any

import yaml

from fuzzyslam import __version__
from fuzzyslam.config import load_config
from fuzzyslam.errors import InputError
from fuzzyslam.reproduce.execute import StepResult, execute
from fuzzyslam.reproduce.plan import Step, _topological

# (name, path in metrics.json's phases.overall, scale, unit)
MEASURES = (
    ("mean position error", ("position_m", "mean"), 100.0, "cm"),
    ("max position error", ("position_m", "max"), 100.0, "cm"),
    ("mean heading error", ("heading_deg", "mean"), 1.0, "deg"),
)


def parse_set(text: str) -> tuple[str, list[Any]]:
    """``KEY=V1,V2,...`` -> (KEY, [values]); each value is read as YAML (0.5, true, text)."""
    key, sep, values = text.partition("=")
    if not sep or not key.strip() or not values.strip():
        raise InputError(text, "--set must be KEY=V1,V2,... (e.g. fgm.freeze_run=1,2)")
    return key.strip(), [yaml.safe_load(v) for v in values.split(",")]


def _nested(key: str, value: Any) -> dict[str, Any]:
    out: Any = value
    for part in reversed(key.split(".")):
        out = {part: out}
    return out


def _merge(a: dict, b: dict) -> dict:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(out.get(k), dict) and isinstance(v, dict) else v
    return out


def grid_configs(
    config: str, sets: list[tuple[str, list[Any]]], outdir: Path
) -> list[tuple[str, dict[str, Any]]]:
    """Write ``gI.yaml`` per grid point into ``outdir`` (and ``base.yaml``, a copy of a
    config file); return [(file name, {key: value})]. Each is loaded once to check it."""
    base = config
    if Path(config).is_file():
        text = Path(config).read_text(encoding="utf-8")
        base_file = outdir / "base.yaml"
        if not base_file.is_file() or base_file.read_text(encoding="utf-8") != text:
            shutil.copyfile(config, base_file)
        base = "base.yaml"
    keys = [k for k, _ in sets]
    points = []
    for i, values in enumerate(itertools.product(*(v for _, v in sets))):
        overrides = dict(zip(keys, values, strict=True))
        doc: dict[str, Any] = {"extends": base}
        for k, v in overrides.items():
            doc = _merge(doc, _nested(k, v))
        name = f"g{i}.yaml"
        text = f"# sweep grid point {i}: {overrides}\n" + yaml.safe_dump(doc, sort_keys=True)
        path = outdir / name
        if not path.is_file() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
        load_config(str(path))  # an unknown key or a bad value: one line, before any step
        points.append((name, overrides))
    return points


def sweep_steps(points: list[tuple[str, dict]], seeds: list[int]) -> list[Step]:
    """simulate -> run -> evaluate for every grid point and seed."""
    steps = []
    for i, (cfg, _) in enumerate(points):
        for s in seeds:
            d = f"g{i}/seed{s}"
            steps += [
                Step(f"{d}/log", ("simulate", cfg, "-o", f"{d}/log.mcap", "--seed", str(s)),
                     (), 16.0, "simulate",
                     (("config", cfg), ("output", f"{d}/log.mcap"), ("seed", s))),
                Step(f"{d}/est", ("run", f"{d}/log.mcap", "-o", f"{d}/est", "--config", cfg),
                     (f"{d}/log",), 4.0, "run",
                     (("log", f"{d}/log.mcap"), ("outdir", f"{d}/est"), ("config", cfg))),
                Step(f"{d}/eval", ("evaluate", f"{d}/log.mcap", f"{d}/est", "-o", f"{d}/eval"),
                     (f"{d}/log", f"{d}/est"), 5.0, "evaluate",
                     (("truth", f"{d}/log.mcap"), ("estimate", f"{d}/est"),
                      ("outdir", f"{d}/eval"))),
            ]  # fmt: skip
    return steps


def step_hashes(steps: list[Step], root: Path) -> dict[str, str]:
    """Content hash of each step: its command, the text of the config files it names,
    the fuzzyslam version and the hashes of its dependencies."""
    out: dict[str, str] = {}
    for s in _topological(steps):
        h = hashlib.sha256()
        h.update(json.dumps([__version__, list(s.argv)]).encode())
        for a in s.argv:
            if a.endswith(".yaml") and (root / a).is_file():
                h.update((root / a).read_bytes())
                if (root / "base.yaml").is_file():
                    h.update((root / "base.yaml").read_bytes())
        for d in sorted(s.deps):
            h.update(out[d].encode())
        out[s.key] = h.hexdigest()
    return out


def _record(root: Path, key: str) -> Path:
    return root / ".sweep" / (key.replace("/", "__") + ".json")


def _output(step: Step) -> str:
    return step.argv[step.argv.index("-o") + 1]


def _stats(values: list[float]) -> dict[str, Any]:
    if not values:
        return {"n": 0, "mean": None, "sd": None, "min": None, "max": None}
    m = sum(values) / len(values)
    sd = (math.sqrt(sum((v - m) ** 2 for v in values) / (len(values) - 1))
          if len(values) > 1 else None)  # fmt: skip
    return {"n": len(values), "mean": m, "sd": sd, "min": min(values), "max": max(values)}


def sweep(
    config: str,
    sets: list[tuple[str, list[Any]]],
    seeds: list[int],
    outdir: str | os.PathLike,
    jobs: int | None = None,
    scheduler: str | None = None,
) -> dict[str, Any]:
    """Run the grid x seeds into ``outdir`` (resumable); return the stdout summary.

    Parameters
    ----------
    config : str
        Base config: a YAML file or an embedded name.
    sets : list of (str, list)
        Swept keys (dotted config paths) and their values; the grid is their product.
    seeds : list of int
        Seeds of every grid point.
    outdir : path
        Output directory; kept between runs (its finished steps are skipped).
    jobs, scheduler
        As for ``reproduce``.

    Returns
    -------
    dict
        The stdout summary: table path, steps run and skipped, the table.
    """
    root = Path(outdir)
    if not sets:
        raise InputError(root, "nothing to sweep: give --set KEY=V1,V2,...")
    if root.exists() and not root.is_dir():
        raise InputError(root, "output path exists and is not a directory")
    if not root.resolve().parent.is_dir():
        raise InputError(root, f"parent directory {root.resolve().parent} does not exist")
    (root / ".sweep").mkdir(parents=True, exist_ok=True)
    points = grid_configs(config, sets, root)
    steps = sweep_steps(points, seeds)
    hashes = step_hashes(steps, root)
    skipped: dict[str, StepResult] = {}
    for s in steps:
        rec = _record(root, s.key)
        try:
            data = json.loads(rec.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if data.get("hash") == hashes[s.key] and (root / _output(s)).exists():
            skipped[s.key] = StepResult(s.key, True, 0.0, data.get("summary"))
    todo = [dataclasses.replace(s, deps=tuple(d for d in s.deps if d not in skipped))
            for s in steps if s.key not in skipped]  # fmt: skip
    for s in todo:
        _record(root, s.key).unlink(missing_ok=True)
        (root / _output(s)).parent.mkdir(parents=True, exist_ok=True)

    def remember(step: Step, res: StepResult) -> None:
        rec = {"hash": hashes[step.key], "command": step.command, "summary": res.summary}
        tmp = _record(root, step.key).with_suffix(".part")
        tmp.write_text(json.dumps(rec, sort_keys=True, default=str), encoding="utf-8")
        os.replace(tmp, _record(root, step.key))

    if todo:
        execute(todo, root, jobs, label="sweep", scheduler=scheduler, on_done=remember)
    rows = []
    for i, (_, overrides) in enumerate(points):
        row: dict[str, Any] = {"point": i, "values": overrides, "measures": {}}
        for name, (a, b), scale, unit in MEASURES:
            vals = []
            for s in seeds:
                m = json.loads((root / f"g{i}/seed{s}/eval/metrics.json").read_text())
                v = m["phases"]["overall"].get(a, {}).get(b)
                if v is not None:
                    vals.append(scale * v)
            row["measures"][f"{name} ({unit})"] = _stats(vals)
        rows.append(row)
    info = {"config": config, "sets": [[k, v] for k, v in sets], "seeds": seeds,
            "steps": len(steps), "ran": len(todo), "skipped": len(skipped)}  # fmt: skip
    (root / "sweep.json").write_text(json.dumps({"info": info, "rows": rows}, indent=2,
                                                sort_keys=True, default=str) + "\n")  # fmt: skip
    _write_table(root / "sweep.md", rows, info)
    return {"command": "sweep", "table": str(root / "sweep.md"),
            "results": str(root / "sweep.json"), **info, "rows": rows}  # fmt: skip


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def _write_table(path: Path, rows: list[dict], info: dict) -> None:
    keys = [k for k, _ in info["sets"]]
    measures = list(rows[0]["measures"]) if rows else []
    head = [*keys, *(f"{m}: mean, sd [min, max]" for m in measures)]
    lines = [
        f"# Sweep of {info['config']}",
        "",
        f"Seeds {', '.join(map(str, info['seeds']))}; {info['steps']} steps, "
        f"{info['ran']} run, {info['skipped']} skipped (unchanged). Errors over the whole "
        "log against the simulator's ground truth.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for r in rows:
        cells = [str(r["values"][k]) for k in keys]
        for m in measures:
            st = r["measures"][m]
            cells.append(f"{_fmt(st['mean'])}, {_fmt(st['sd'])} [{_fmt(st['min'])}, "
                         f"{_fmt(st['max'])}]")  # fmt: skip
        lines.append("| " + " | ".join(cells) + " |")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
