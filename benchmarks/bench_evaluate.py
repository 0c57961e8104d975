"""Benchmark of the ``evaluate`` and ``map`` steps of ``reproduce``: CPU per step, old
against new code side by side.

    python benchmarks/bench_evaluate.py --baseline main [--tree DIR] [--repeat 1]

On one seed of ``reproduce --quick`` (``--tree``: an existing output made with its logs,
``--keep-logs`` or one seed; else one is made first with the new code), every ``map``
and ``evaluate`` step runs with the old code (git revision ``--baseline``, exported) and
the new (the installed), alternately, into a scratch directory, two ways:

- ``command``: the step as its ``fuzzyslam`` command line in a fresh process (what a
  user pays: the imports included), CPU time (user + sys) of the process;
- ``in_worker``: every step of the list run twice through ``reproduce``'s ``run_step``
  in one process, as a pool worker runs them, the CPU time (``time.process_time``) of the
  second run of each (the cost per step once the imports are paid), and the CPU of the
  imports a worker pays once (the stage entries and what they load on demand).

Prints one JSON object: per step and kind, old and new CPU seconds and their ratio, the
load average before and after, and whether the two codes' outputs are the same (every
non-PNG file byte for byte, summary.json's timings aside; the PNG files by name).

``--reproduce``: instead, the whole ``reproduce --quick --seeds 1 --jobs 2``, old and new
alternately ``--repeat`` times, each in a fresh process whose pool workers record the CPU
time of every step (``run_step`` wrapped): per kind of step (simulate, run, map,
evaluate) the CPU summed over the steps, the workers' CPU outside the steps (imports;
the old code imports on demand, the new in the parent before the fork), the parent's own
CPU and the whole tree's (user + sys of every process), and the wall time.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))


def worker(tree: Path, out: Path, keys: list[str]) -> None:
    """Run the steps ``keys`` of seed 0 twice in this process; print JSON (CPU s)."""
    os.environ["FUZZYSLAM_NO_PROGRESS"] = "1"
    t0 = time.process_time()
    import importlib

    from fuzzyslam.reproduce import execute
    from fuzzyslam.reproduce.plan import QUICK, build_plan

    for m in execute.STAGES.values():
        importlib.import_module(m)
    steps = {s.key.split("/", 1)[1]: s for s in build_plan([0], QUICK)}
    result: dict = {"import_s": 0.0, "first_s": {}, "steps_s": {}}
    result["import_s"] = time.process_time() - t0
    for rep in range(2):
        for k in keys:
            s = steps[k]
            call = dict(s.call)
            dest = out / f"run{rep}" / k
            shutil.rmtree(dest, ignore_errors=True)
            dest.parent.mkdir(parents=True, exist_ok=True)
            call["outdir"] = str(dest)
            c0 = time.process_time()
            ok, _sec, _summary, err, *_ = execute.run_step(s.kind, tuple(call.items()), str(tree))
            if not ok:
                raise SystemExit(f"{k}: {err}")
            result["first_s" if rep == 0 else "steps_s"][k] = time.process_time() - c0
    print(json.dumps(result))


def drive(out: Path, record: Path) -> None:
    """``reproduce --quick --seeds 1 --jobs 2`` into ``out`` in this process, its pool
    workers appending each step's CPU (s) to ``record`` (JSON lines)."""
    import resource

    os.environ["FUZZYSLAM_NO_PROGRESS"] = "1"
    c0 = time.process_time()
    from fuzzyslam.reproduce import execute, stage

    real = execute.run_step

    def run_step(kind, call, root):
        t0, first = time.process_time(), not hasattr(run_step, "seen")
        if first:  # the worker's CPU before its first step: the fork's and imports
            run_step.seen = True
            with open(record, "a") as f:
                f.write(json.dumps({"pid": os.getpid(), "before_first_s": t0}) + "\n")
        res = real(kind, call, root)
        with open(record, "a") as f:
            f.write(json.dumps({"pid": os.getpid(), "kind": kind, "cpu_s": time.process_time() - t0,
                                "cpu_total_s": time.process_time()}) + "\n")  # fmt: skip
        return res

    run_step.__module__, run_step.__qualname__ = real.__module__, real.__qualname__
    execute.run_step = run_step  # the forked workers run it (pickled by name)
    w0 = time.perf_counter()
    stage.reproduce(out, [0], quick=True, jobs=2)
    wall = time.perf_counter() - w0
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(json.dumps({"parent_cpu_s": time.process_time() - c0, "wall_s": wall,
                      "children_cpu_s": ch.ru_utime + ch.ru_stime}))  # fmt: skip


def reproduce_side_by_side(args, src: Path, work: Path) -> dict:
    """``drive`` with the old and the new code alternately; CPU per kind of step."""
    from sidebyside import load, same_outputs

    before = load()
    res: dict[str, list[dict]] = {"old": [], "new": []}
    for rep in range(args.repeat):
        for v in ("old", "new"):
            out, record = work / f"reproduce_{v}{rep}", work / f"steps_{v}{rep}.jsonl"
            shutil.rmtree(out, ignore_errors=True)
            record.unlink(missing_ok=True)
            env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "MPLBACKEND": "Agg"}
            env.pop("PYTHONPATH", None)
            if v == "old":
                env["PYTHONPATH"] = str(src)
            cmd = [sys.executable, __file__, "--drive", str(out), str(record)]
            p = subprocess.run(cmd, env=env, cwd=tempfile.gettempdir(), capture_output=True,
                               text=True)  # fmt: skip
            if p.returncode != 0:
                raise RuntimeError(p.stderr.strip()[-800:])
            top = json.loads(p.stdout.strip().splitlines()[-1])
            rows = [json.loads(ln) for ln in record.read_text().splitlines()]
            kinds: dict[str, float] = defaultdict(float)
            last: dict[int, float] = {}
            steps_cpu = defaultdict(float)
            for r in rows:
                if "kind" in r:
                    kinds[r["kind"]] += r["cpu_s"]
                    steps_cpu[r["pid"]] += r["cpu_s"]
                    last[r["pid"]] = r["cpu_total_s"]
            outside = sum(last[pid] - steps_cpu[pid] for pid in last)
            res[v].append({"by_kind_s": dict(kinds), "workers_outside_steps_s": outside,
                           "parent_s": top["parent_cpu_s"], "wall_s": top["wall_s"],
                           "tree_cpu_s": top["parent_cpu_s"] + top["children_cpu_s"]})  # fmt: skip

    def best(v: str, get) -> float:
        return min(get(r) for r in res[v])

    keys = ["simulate", "run", "map", "evaluate"]
    table = {}
    for k in keys:
        table[f"{k} (sum over steps)"] = tuple(
            best(v, lambda r, k=k: r["by_kind_s"].get(k, 0.0)) for v in ("old", "new")
        )
    table["workers outside steps (imports)"] = (
        best("old", lambda r: r["workers_outside_steps_s"]),
        best("new", lambda r: r["workers_outside_steps_s"]),
    )
    table["parent (plan, preload, report, summary.png)"] = (
        best("old", lambda r: r["parent_s"]), best("new", lambda r: r["parent_s"]))  # fmt: skip
    table["whole tree CPU"] = (best("old", lambda r: r["tree_cpu_s"]),
                               best("new", lambda r: r["tree_cpu_s"]))  # fmt: skip
    table["wall"] = (best("old", lambda r: r["wall_s"]), best("new", lambda r: r["wall_s"]))
    return {"reproduce": "--quick --seeds 1 --jobs 2", "repeat": args.repeat,
            "best_of_repeats_s": {k: {"old": round(o, 2), "new": round(n, 2),
                                      "ratio": round(o / n, 2) if n else None}
                                  for k, (o, n) in table.items()},
            "runs": res, "same_outputs": same_outputs(work / "reproduce_old0",
                                                      work / "reproduce_new0"),
            "load_before": before, "load_after": load()}  # fmt: skip


def run_worker(tree: Path, out: Path, keys: list[str], src: Path | None) -> dict:
    """``worker`` in a fresh process with the old (``src``) or the new code."""
    env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "MPLBACKEND": "Agg"}
    env.pop("PYTHONPATH", None)
    if src is not None:
        env["PYTHONPATH"] = str(src)
    cmd = [sys.executable, __file__, "--worker", str(tree), str(out), *keys]
    p = subprocess.run(cmd, env=env, cwd=tempfile.gettempdir(), capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(p.stderr.strip()[-800:])
    return json.loads(p.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", metavar="REV", default="main")
    ap.add_argument("--tree", type=Path, default=None,
                    help="a `reproduce --quick` output with seed 0's logs")  # fmt: skip
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--reproduce", action="store_true",
                    help="the whole reproduce --quick --seeds 1: CPU per kind of step")  # fmt: skip
    ap.add_argument("--worker", nargs="+", help=argparse.SUPPRESS)
    ap.add_argument("--drive", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.worker:
        worker(Path(args.worker[0]), Path(args.worker[1]), args.worker[2:])
        return
    if args.drive:
        drive(Path(args.drive[0]), Path(args.drive[1]))
        return
    from sidebyside import export_revision, load, run_cli, same_outputs

    from fuzzyslam.reproduce.plan import QUICK, build_plan

    work = args.workdir or Path(tempfile.mkdtemp(prefix="bench_evaluate."))
    work.mkdir(parents=True, exist_ok=True)
    if args.reproduce:
        print(json.dumps(reproduce_side_by_side(args, export_revision(args.baseline), work),
                         indent=1))  # fmt: skip
        return
    tree = args.tree
    if tree is None:
        tree = work / "tree"
        run_cli(["reproduce", "--quick", "--seeds", "1", "--keep-logs", "-o", str(tree)], None)
    tree = tree.resolve()
    src = export_revision(args.baseline)
    before = load()
    steps = [s for s in build_plan([0], QUICK) if s.kind in ("map", "evaluate")]
    keys = [s.key.split("/", 1)[1] for s in steps]
    kind = {s.key.split("/", 1)[1]: s.kind for s in steps}
    cpu: dict[str, dict[str, list[float]]] = defaultdict(lambda: {"old": [], "new": []})
    inw: dict[str, dict[str, list[float]]] = defaultdict(lambda: {"old": [], "new": []})
    imports: dict[str, list[float]] = {"old": [], "new": []}
    for _ in range(args.repeat):
        for s, k in zip(steps, keys, strict=True):
            for v in ("old", "new"):
                argv = list(s.argv)
                o = argv.index("-o")
                argv[o + 1] = str(work / f"command_{v}" / k)
                shutil.rmtree(argv[o + 1], ignore_errors=True)
                Path(argv[o + 1]).parent.mkdir(parents=True, exist_ok=True)
                _wall, c = run_cli(argv, src if v == "old" else None, cwd=tree)
                cpu[k][v].append(c)
        for v in ("old", "new"):
            r = run_worker(tree, work / f"worker_{v}", keys, src if v == "old" else None)
            imports[v].append(r["import_s"])
            for k in keys:
                inw[k][v].append(r["steps_s"][k])

    def row(d: dict[str, list[float]]) -> dict:
        old, new = min(d["old"]), min(d["new"])
        return {"old_s": round(old, 2), "new_s": round(new, 2), "ratio": round(old / new, 2)}

    def by_kind(d: dict) -> dict:
        tot: dict[str, dict[str, list[float]]] = {}
        for kd in ("map", "evaluate"):
            ks = [k for k in keys if kind[k] == kd]
            tot[kd] = {v: [sum(min(d[k][v]) for k in ks)] for v in ("old", "new")}
        return {kd: row(x) for kd, x in tot.items()}

    print(json.dumps({
        "baseline": args.baseline, "tree": str(tree), "repeat": args.repeat,
        "cpu_best_of_repeats": True,
        "command": {"per_step": {k: row(cpu[k]) for k in keys}, "by_kind_total": by_kind(cpu)},
        "in_worker": {"per_step": {k: row(inw[k]) for k in keys}, "by_kind_total": by_kind(inw),
                      "stage_imports": row(imports)},
        "same_outputs_command": same_outputs(work / "command_old", work / "command_new"),
        "same_outputs_in_worker": same_outputs(work / "worker_old" / "run1",
                                               work / "worker_new" / "run1"),
        "load_before": before, "load_after": load(),
    }, indent=1))  # fmt: skip


if __name__ == "__main__":
    main()
