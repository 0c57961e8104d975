"""Old against new code, side by side in one benchmark run (imported by the bench_*.py).

The old code is a git revision (``--baseline main``) exported with ``git archive`` into a
temporary directory and put first on PYTHONPATH of its processes; the new code is the
installed one. Each command runs in a fresh process, alternating old and new ``repeat``
times, so both see the same load; a process's CPU time (user + sys, from
``resource.getrusage(RUSAGE_CHILDREN)``) is less sensitive to the load than its wall time.
"""

from __future__ import annotations

import io
import json
import os
import resource
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def export_revision(rev: str) -> Path:
    """A temporary directory holding ``fuzzyslam/`` of git revision ``rev`` (with its
    configs placed as the installed package has them: fuzzyslam/configs)."""
    out = Path(tempfile.mkdtemp(prefix=f"fuzzyslam-{rev.replace('/', '_')}."))
    for part, dest in (("fuzzyslam", out), ("configs", out / "fuzzyslam")):
        tar = subprocess.run(["git", "-C", str(ROOT), "archive", rev, part],
                             check=True, capture_output=True).stdout  # fmt: skip
        with tarfile.open(fileobj=io.BytesIO(tar)) as t:
            t.extractall(dest, filter="data")
    if not any((out / "fuzzyslam" / "configs").glob("*.yaml")):
        raise RuntimeError(f"no configs in revision {rev}")
    return out


def compiled(code: Path) -> None:
    """Byte-compile the package under ``code`` (``__pycache__``, as an installed package
    has it): with PYTHONDONTWRITEBYTECODE set, as on some machines, every command would
    otherwise compile fuzzyslam from source (about 60 ms), and a tree that a test run
    happened to compile would start faster than one that no test touched."""
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(code)], check=True,
                   stdout=subprocess.DEVNULL)  # fmt: skip


def run_cli(args: list[str], src: Path | None, env: dict[str, str] | None = None,
            cwd: Path | None = None) -> tuple[float, float]:  # fmt: skip
    """(wall s, CPU s) of ``python -m fuzzyslam ARGS`` in a fresh process; ``src``: a
    directory put first on PYTHONPATH (the old code), None: the installed code. Paths
    in ARGS must be absolute (the process runs in ``cwd``, default the temp directory)."""
    env = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "MPLBACKEND": "Agg", **(env or {})}
    if src is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(src), env.get("PYTHONPATH", "")]).rstrip(
            os.pathsep)
    else:
        env.pop("PYTHONPATH", None)
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    # not in the repository: ``-m`` puts the working directory first on sys.path
    p = subprocess.run([sys.executable, "-m", "fuzzyslam", *args], env=env,
                       cwd=cwd or tempfile.gettempdir(),
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)  # fmt: skip
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise RuntimeError(f"fuzzyslam {' '.join(args)} failed: {p.stderr.strip()[-500:]}")
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    return wall, cpu


def side_by_side(
    make_args, baseline: Path | None, repeat: int, candidate: Path | None = None
) -> dict[str, dict]:
    """Run ``make_args(variant)`` (variant "old" or "new"; the command's arguments)
    alternately ``repeat`` times each; per variant the best and median wall and CPU s.
    ``candidate``: the new code's directory (an exported revision), None: the installed."""
    times: dict[str, list[tuple[float, float]]] = {"old": [], "new": []}
    variants = (["old"] if baseline is not None else []) + ["new"]
    for code in (baseline, candidate or ROOT / "fuzzyslam"):
        if code is not None:
            compiled(code)
    for _ in range(repeat):
        for v in variants:
            times[v].append(run_cli(make_args(v), baseline if v == "old" else candidate))
    out = {}
    for v in variants:
        walls, cpus = [t[0] for t in times[v]], [t[1] for t in times[v]]
        out[v] = {"wall_best_s": round(min(walls), 2),
                  "wall_median_s": round(statistics.median(walls), 2),
                  "cpu_best_s": round(min(cpus), 2),
                  "cpu_median_s": round(statistics.median(cpus), 2)}  # fmt: skip
    if baseline is not None:
        out["speedup_cpu_median"] = round(out["old"]["cpu_median_s"] /
                                          out["new"]["cpu_median_s"], 2)  # fmt: skip
        out["speedup_wall_median"] = round(out["old"]["wall_median_s"] /
                                           out["new"]["wall_median_s"], 2)  # fmt: skip
    return out


def load() -> str:
    """The machine's load averages and cores, for the printed figures."""
    a, b, c = os.getloadavg()
    return f"load average {a:.2f} {b:.2f} {c:.2f} on {os.cpu_count()} cores"


# what the outputs record of the machine rather than of the maths, left out of a comparison:
# JSON keys anywhere (run and map summary.json, results.json's step times), results.json's
# Cost rows, report.md's Cost and wall-time lines; "output": the folder old and new wrote
TIMINGS = frozenset({"build_seconds", "wall_seconds", "output", "real_time_factor",
                     "wall_time_s", "seconds", "pid", "wall_s"})  # fmt: skip


def untimed(name: str, data: bytes) -> bytes:
    """A file's bytes without what :data:`TIMINGS` says it records of the machine."""

    def mask(obj):
        if isinstance(obj, dict):
            if str(obj.get("group", "")).startswith("Cost"):
                return None
            return {k: mask(v) for k, v in obj.items() if k not in TIMINGS}
        return [mask(v) for v in obj] if isinstance(obj, list) else obj

    if name.endswith(".json"):
        return json.dumps(mask(json.loads(data)), sort_keys=True).encode()
    if name == "report.md":
        keep = [ln for ln in data.decode().splitlines()
                if "Cost" not in ln and "wall time" not in ln]  # fmt: skip
        return "\n".join(keep).encode()
    return data


def same_outputs(a: Path, b: Path) -> dict:
    """Two output folders (old and new code) file by file: every file byte for byte, but
    summary.json, results.json and report.md without their timings (:func:`untimed`);
    PNG files listed apart (``different_png``: a figure's bytes may change with the
    drawing code, not with the maths). ``identical``: nothing differs, PNGs included."""
    fa = {p.relative_to(a) for p in a.rglob("*") if p.is_file()}
    fb = {p.relative_to(b) for p in b.rglob("*") if p.is_file()}
    differ, png = [], []
    for r in sorted(fa & fb):
        x, y = (a / r).read_bytes(), (b / r).read_bytes()
        if x != y and r.name in ("summary.json", "results.json", "report.md"):
            x, y = untimed(r.name, x), untimed(r.name, y)
        if x != y:
            (png if r.suffix == ".png" else differ).append(str(r))
    out = {"files_compared": len(fa & fb), "only_old": sorted(map(str, fa - fb)),
           "only_new": sorted(map(str, fb - fa)), "different": differ,
           "different_png": png}  # fmt: skip
    out["identical"] = not (out["only_old"] or out["only_new"] or differ or png)
    return out
