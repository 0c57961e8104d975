"""The heading aid's hot functions, old against new code on the inputs of a real run.

    python benchmarks/bench_heading_path.py [LOG.mcap FGMDIR] [--baseline REV] [--repeat 5]

Runs ``fuzzyslam run LOG --map FGMDIR --fix heading`` in this process with the FLM
builder (``maps.flm.build_flm``), the Hough accumulator (``maps.hough_accumulator``) and
the tangent fit (``maps.tangent.fit_walls``) wrapped to record their inputs, then calls
each function of the old code (its module file from git revision REV, default main,
loaded under another name) and of this code on the recorded inputs: whether the results
are bit for bit the same, and their CPU time (process time; old and new alternate
``--repeat`` times and the best is printed: the least disturbed by other processes on a
shared machine). The FLM builder is timed from a cold cache, as in a run (a fresh
process each, in order: the cache fills as the run goes). Without LOG and FGMDIR it
simulates the paper log and builds its map in a temporary directory first.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import json
import os
import pickle
import subprocess
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("FUZZYSLAM_NO_PROGRESS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

FUNCS = {  # name: (module, function)
    "flm": ("fuzzyslam/maps/flm.py", "build_flm"),
    "hough": ("fuzzyslam/maps/hough_accumulator.py", "hough_accumulator"),
    "fit": ("fuzzyslam/maps/tangent.py", "fit_walls"),
}


def record(log: Path, fgm: Path, out: Path) -> None:
    """Run the heading fixes in this process, recording the three functions' inputs."""
    import fuzzyslam.maps.flm as F
    import fuzzyslam.maps.hough as H
    import fuzzyslam.maps.tangent as T
    from fuzzyslam.cli import main

    rec: dict[str, list] = {k: [] for k in FUNCS}

    def wrap(mod, name, key):
        f = getattr(mod, name)

        def g(*a, **kw):
            rec[key].append((a, kw))
            return f(*a, **kw)

        setattr(mod, name, g)

    wrap(F, "build_flm", "flm")
    wrap(H, "hough_accumulator", "hough")
    wrap(T, "fit_walls", "fit")
    with tempfile.TemporaryDirectory() as d, contextlib.redirect_stdout(io.StringIO()):
        try:
            main(["run", str(log), "--map", str(fgm), "--fix", "heading", "-o", f"{d}/C"])
        except SystemExit as exc:
            if exc.code:
                raise
    out.write_bytes(pickle.dumps(rec))


def load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def same(a, b) -> bool:
    """Bit-for-bit equality of results (arrays, dataclasses, tuples, floats)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if hasattr(a, "__dataclass_fields__"):
        return all(same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    if isinstance(a, float):
        return np.float64(a).tobytes() == np.float64(b).tobytes()
    return a == b


def time_in_child(corpus: Path, key: str, src: Path | None) -> float:
    """CPU s of one pass over the recorded calls in a fresh process (cold caches)."""
    code = (
        "import pickle, sys, time, importlib.util\n"
        f"rec = pickle.loads(open({str(corpus)!r}, 'rb').read())[{key!r}]\n"
        f"path, name = {FUNCS[key]!r}\n"
        f"src = {None if src is None else str(src)!r}\n"
        "if src is None:\n"
        "    import importlib; m = importlib.import_module(path[:-3].replace('/', '.'))\n"
        "else:\n"
        "    spec = importlib.util.spec_from_file_location('old_mod', f'{src}/{path}')\n"
        "    m = importlib.util.module_from_spec(spec); sys.modules['old_mod'] = m\n"
        "    spec.loader.exec_module(m)\n"
        "f = getattr(m, name)\n"
        "c = time.process_time()\n"
        "for a, kw in rec:\n"
        "    f(*a, **kw)\n"
        "print(time.process_time() - c)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("log", nargs="?", default=None)
    ap.add_argument("fgm", nargs="?", default=None)
    ap.add_argument("--baseline", metavar="REV", default="main")
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).parent))
    from sidebyside import export_revision
    from sidebyside import load as load_avg

    work = Path(tempfile.mkdtemp(prefix="bench_heading."))
    if a.log and a.fgm:
        log, fgm = Path(a.log), Path(a.fgm)
    else:
        log, fgm = work / "paper.mcap", work / "fgm"
        run = [sys.executable, "-m", "fuzzyslam"]
        subprocess.run([*run, "simulate", "paper", "-o", str(log)], check=True,
                       stdout=subprocess.DEVNULL)  # fmt: skip
        subprocess.run([*run, "run", str(log), "-o", str(work / "AB")], check=True,
                       stdout=subprocess.DEVNULL)  # fmt: skip
        subprocess.run([*run, "map", str(log), "--trajectory", str(work / "AB/trajectory.tum"),
                        "-o", str(fgm)], check=True, stdout=subprocess.DEVNULL)  # fmt: skip
    corpus = work / "corpus.pkl"
    record(log, fgm, corpus)
    rec = pickle.loads(corpus.read_bytes())
    src = export_revision(a.baseline)
    before = load_avg()
    for key, (path, name) in FUNCS.items():
        new = getattr(importlib.import_module(path[:-3].replace("/", ".")), name)
        old = getattr(load(f"old_{key}", src / path), name)
        differ = sum(not same(old(*x, **kw), new(*x, **kw)) for x, kw in rec[key])
        times: dict[str, list[float]] = {"old": [], "new": []}
        for _ in range(a.repeat):
            times["old"].append(time_in_child(corpus, key, src))
            times["new"].append(time_in_child(corpus, key, None))
        best = {v: min(t) for v, t in times.items()}
        print(json.dumps({"function": f"{path}:{name}", "calls": len(rec[key]),
                          "results_differ": differ, "baseline": a.baseline,
                          "cpu_best_s": {v: round(t, 3) for v, t in best.items()},
                          "cpu_median_s": {v: round(float(np.median(t)), 3)
                                           for v, t in times.items()},
                          "speedup_best": round(best["old"] / best["new"], 2),
                          "load_before": before, "load_after": load_avg()}))  # fmt: skip


if __name__ == "__main__":
    main()
