"""Repeatability of ``sweep`` and ``reproduce``: a ``--set seed`` (which every simulate
step's ``--seed`` would silently override) is refused; the seeds the command line takes
are those a config may hold; a sweep over recorded logs writes the same files wherever it
runs (and a moved sweep folder goes on with every step skipped); a step runs again when
the code changed, not only the version number. Fast: micro logs, in-process commands."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from test_robust_logs import cli, error_lines

from fuzzyslam.errors import EXIT_INPUT, EXIT_USAGE, InputError

MICRO = Path(__file__).with_name("micro.yaml")
TIMING = ("wall_time_s", "real_time_factor", "seconds", "wall_s")  # differ between runs


@pytest.fixture(scope="module")
def micro_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A simulated log of the micro scenario (one tenth of a lap, 0.8 MB)."""
    out = tmp_path_factory.mktemp("micro") / "log.mcap"
    code, _, err = cli("simulate", MICRO, "-o", out)
    assert code == 0, err
    return out


def _one_error(code: int, out: str, err: str, exit_code: int) -> str:
    lines = error_lines(err)
    assert code == exit_code, err
    assert out == "" and len(lines) == 1, err
    return lines[0]


# --- 1: seed in --set -----------------------------------------------------------------


def test_seed_in_set_is_refused_pointing_to_the_seed_options(tmp_path: Path) -> None:
    """``sweep --set seed=5,6`` and ``reproduce --set seed=3``: one line naming the option
    and the seed options, exit 3 (as ``extends``), nothing written."""
    missing = tmp_path / "missing"  # a later check's error, were seed not refused first
    line = _one_error(*cli("sweep", MICRO, "--set", "seed=5,6", "--seeds", "1",
                           "-o", missing / "sw"), EXIT_INPUT)  # fmt: skip
    assert line.startswith("fuzzyslam: error: --set seed=5,6: 'seed' cannot be set"), line
    assert line.endswith("choose the seeds with --seeds N"), line
    line = _one_error(*cli("reproduce", "--set", "seed=3", "-o", missing / "r"), EXIT_INPUT)
    assert line.startswith("fuzzyslam: error: --set seed=3: 'seed' cannot be set"), line
    assert line.endswith("--seeds N and --first-seed S"), line
    assert not missing.exists()


def test_seed_is_refused_by_the_sweep_and_reproduce_functions_too(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The Python entries (``check_grid``, ``check_suite``) refuse it as the CLI does."""
    import fuzzyslam.reproduce.sweep as sw
    import fuzzyslam.reproduce.sweep_plot as plot
    from fuzzyslam.reproduce.overrides import check_suite
    from fuzzyslam.reproduce.plan import QUICK

    monkeypatch.setattr(sw, "execute", lambda *a, **k: {})  # no step may run
    monkeypatch.setattr(plot, "plot_sweep", lambda *a, **k: [])
    out = tmp_path / "sw"
    with pytest.raises(InputError, match=r"--set seed=5,6: 'seed' cannot be set"):
        sw.sweep(str(MICRO), [("robot.wheel_noise", [0.01]), ("seed", [5, 6])], [1], out)
    assert not out.exists()
    with pytest.raises(InputError, match=r"--set seed=3: 'seed' cannot be set"):
        check_suite(QUICK, {"seed": 3})


# --- 4: the seeds of the command line and of a config ---------------------------------


def test_command_line_seeds_have_the_config_seed_bound(tmp_path: Path) -> None:
    """A config's ``seed`` is refused above 1e9, and so is every seed of the command line:
    ``simulate --seed``, ``reproduce --first-seed`` (and its last seed), ``sweep
    --seeds``; 1e9 itself is a seed both take."""
    top = 1_000_000_000
    cfg = tmp_path / "big.yaml"
    cfg.write_text(MICRO.read_text(encoding="utf-8") + f"seed: {top + 1}\n", encoding="utf-8")
    line = _one_error(*cli("simulate", cfg, "-o", tmp_path / "a.mcap"), EXIT_INPUT)
    assert "'seed' must be <= 1000000000" in line, line
    missing = tmp_path / "missing"  # no command may get as far as its output
    for args in (
        ("simulate", MICRO, "--seed", top + 1, "-o", tmp_path / "b.mcap"),
        ("reproduce", "--first-seed", top + 1, "-o", missing / "r"),
        ("reproduce", "--first-seed", top - 1, "--seeds", 3, "-o", missing / "r"),
        ("sweep", MICRO, "--set", "robot.wheel_noise=0.1", "--seeds", top + 2, "-o",
         missing / "s"),
    ):  # fmt: skip
        line = _one_error(*cli(*args), EXIT_USAGE)
        assert str(top) in line, line
    assert not (tmp_path / "b.mcap").exists() and not missing.exists()
    cfg.write_text(MICRO.read_text(encoding="utf-8") + f"seed: {top}\n", encoding="utf-8")
    code, _, err = cli("simulate", cfg, "-o", tmp_path / "c.mcap")
    assert code == 0, err
    code, _, err = cli("simulate", MICRO, "--seed", top, "-o", tmp_path / "d.mcap")
    assert code == 0, err
    assert (tmp_path / "c.mcap").read_bytes() == (tmp_path / "d.mcap").read_bytes()


# --- 2: a sweep over recorded logs, wherever it runs ---------------------------------


def _untimed(obj):
    """A JSON value without its timing fields."""
    if isinstance(obj, dict):
        return {k: _untimed(v) for k, v in obj.items() if k not in TIMING}
    if isinstance(obj, list):
        return [_untimed(v) for v in obj]
    return obj


def _snapshot(root: Path) -> dict[str, object]:
    """Every file of a sweep folder: link -> its target, JSON -> its value without the
    timing fields, any other file -> its bytes."""
    out: dict[str, object] = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        if p.is_symlink():
            out[rel] = ("link", os.readlink(p))
        elif p.is_file() and p.suffix == ".json":
            out[rel] = _untimed(json.loads(p.read_text(encoding="utf-8")))
        elif p.is_file():
            out[rel] = p.read_bytes()
    return out


# Sweeps run in a fresh interpreter, never in the test's own process: the engine forks its
# pool from the process that runs it, and a process that has run OpenCV with its threads
# (another test of this xdist worker) forks children that hang in cv2.setNumThreads
SWEEPS = """
import contextlib, io, json, os, sys
from pathlib import Path
import fuzzyslam.reproduce.sweep as sw
from fuzzyslam.cli import main
out = []
for op in json.loads(sys.argv[1]):
    if "rename" in op:
        Path(op["rename"][1]).parent.mkdir(parents=True, exist_ok=True)
        os.rename(*op["rename"])
    if "package_dir" in op:  # the sources the step hashes hold (a copy of some)
        sw.PACKAGE_DIR = Path(op["package_dir"])
    if "numpy" in op and hasattr(sw, "_library_versions"):  # another numpy version
        versions = dict(sw._library_versions())
        sw._library_versions = lambda: {**versions, "numpy": op["numpy"]}
    os.chdir(op["cwd"])
    text, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(text), contextlib.redirect_stderr(err):
        try:
            main(op["args"])
        except SystemExit as exc:
            assert not exc.code, err.getvalue()
    out.append(json.loads(text.getvalue()))
print(json.dumps(out))
"""


def sweep_args(out: str, config: Path = MICRO) -> list[str]:
    """``sweep CONFIG --logs 'runs/*/log.mcap' -o OUT`` (a glob relative to the working
    directory, as typed)."""
    return ["sweep", str(config), "--set", "slam.use_encoders=true",
            "--logs", "runs/*/log.mcap", "-o", out, "-j", "1"]  # fmt: skip


def run_sweeps(ops: list[dict]) -> list[dict]:
    """Run ``ops`` (each: ``cwd``, ``args``, and optionally ``rename`` [src, dst] first,
    ``package_dir``, ``numpy``) one after the other in one fresh interpreter through
    the CLI; their JSON summaries."""
    p = subprocess.run([sys.executable, "-c", SWEEPS, json.dumps(ops, default=str)],
                       capture_output=True, text=True, timeout=300,
                       env={**os.environ, "MPLBACKEND": "Agg"})  # fmt: skip
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def _run_only(folder: Path) -> Path:
    """The micro config looking for the ground truth where the log has none: a sweep of
    it runs each log and evaluates nothing (a fast sweep)."""
    cfg = folder / "cfg.yaml"
    cfg.write_text(MICRO.read_text(encoding="utf-8") + "topics: {ground_truth: /none}\n",
                   encoding="utf-8")  # fmt: skip
    return cfg


def _logs_in(folder: Path, log: Path) -> None:
    (folder / "runs" / "x").mkdir(parents=True)
    shutil.copyfile(log, folder / "runs" / "x" / "log.mcap")


@pytest.mark.slow  # end to end (sweeps or run + evaluate in subprocesses)
def test_a_sweep_over_logs_writes_the_same_files_wherever_it_runs(
    tmp_path: Path, micro_log: Path
) -> None:
    """The same sweep (``--logs 'runs/*/log.mcap'``, run and evaluate) in two folders (at
    once, two processes): the same files byte for byte (sweep.json, sweep.md, the
    figure, every step's outputs and records), timing fields aside, none naming the
    folder."""
    procs = []
    for d in ("A", "B"):
        _logs_in(tmp_path / d, micro_log)
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "fuzzyslam", *sweep_args("sw")], cwd=tmp_path / d,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            env={**os.environ, "MPLBACKEND": "Agg"}))  # fmt: skip
    for p in procs:
        out, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
        summary = json.loads(out)
        assert summary["steps"] == 2 and summary["ran"] == 2  # run and evaluate
    a, b = _snapshot(tmp_path / "A" / "sw"), _snapshot(tmp_path / "B" / "sw")
    assert {"sweep.json", "g0/log0_log/eval/metrics.json", "g0/log0_log/est/summary.json",
            "g0/log0_log/eval/report.md"} <= set(a)  # fmt: skip
    assert a == b
    for rel, v in a.items():
        assert str(tmp_path) not in str(v), rel
    info = json.loads((tmp_path / "A" / "sw" / "sweep.json").read_text())["info"]
    assert info["logs"] == ["../runs/x/log.mcap"]
    est = json.loads((tmp_path / "A/sw/g0/log0_log/est/summary.json").read_text())
    assert est["log"] == "logs/log0_log/log.mcap"


@pytest.mark.slow  # end to end (sweeps or run + evaluate in subprocesses)
def test_a_moved_sweep_folder_goes_on_with_every_step_skipped(
    tmp_path: Path, micro_log: Path
) -> None:
    """A finished sweep moved with its logs (the whole tree), then its folder alone two
    levels deeper, and the sweep rerun each time: its log links are pointed again, its
    steps' hashes are the same, nothing runs (a run only: the evaluations' hashes do not
    depend on the folder either, as the previous test's identical records show)."""
    a, b = tmp_path / "A", tmp_path / "B"
    _logs_in(a, micro_log)
    cfg = _run_only(tmp_path)
    first = run_sweeps([{"cwd": a, "args": sweep_args("sw", cfg)}])[0]
    assert first["ran"] == 1
    before = _snapshot(a / "sw")
    steps = [k for k in before if k.startswith(("g0/", ".sweep/"))]
    assert "g0/log0_log/est/summary.json" in steps
    again = run_sweeps([
        {"rename": [a, b], "cwd": b, "args": sweep_args("sw", cfg)},  # logs and sweep
        {"rename": [b / "sw", b / "deep/er/sw"], "cwd": b,  # the sweep folder alone
         "args": sweep_args("deep/er/sw", cfg)},
    ])  # fmt: skip
    assert [(s["ran"], s["skipped"]) for s in again] == [(0, 1), (0, 1)]
    moved = _snapshot(b / "deep" / "er" / "sw")
    assert moved["logs/log0_log/log.mcap"] == ("link", "../../../../../runs/x/log.mcap")
    assert [moved[k] for k in steps] == [before[k] for k in steps]


# --- 3: the code in the step hash ---------------------------------------------------


@pytest.mark.slow  # end to end (sweeps or run + evaluate in subprocesses)
def test_a_step_runs_again_when_the_sources_or_a_library_changed(
    tmp_path: Path, micro_log: Path
) -> None:
    """The sweep's step hashes hold the package's sources (here a copy of two of its
    files stands for them) and the libraries' versions: the same sources elsewhere skip
    the step, a byte changed in one or another numpy version runs it again."""
    import fuzzyslam.reproduce.sweep as sw

    pkg = Path(sw.__file__).resolve().parents[1]
    sources = []
    for i, text in enumerate(["same", "same", "changed"]):
        d = tmp_path / f"src{i}"
        (d / "reproduce").mkdir(parents=True)
        shutil.copyfile(pkg / "config.py", d / "config.py")
        body = (pkg / "reproduce" / "sweep.py").read_text(encoding="utf-8")
        (d / "reproduce" / "sweep.py").write_text(body + f"# {text}\n", encoding="utf-8")
        sources.append(d)
    _logs_in(tmp_path, micro_log)
    args = sweep_args("sw", _run_only(tmp_path))
    done = run_sweeps([
        {"cwd": tmp_path, "args": args, "package_dir": sources[0]},
        {"cwd": tmp_path, "args": args, "package_dir": sources[1]},  # the same bytes
        {"cwd": tmp_path, "args": args, "package_dir": sources[2]},  # a comment added
        {"cwd": tmp_path, "args": args, "numpy": "0.0.1"},
    ])  # fmt: skip
    assert [(s["steps"], s["ran"], s["skipped"]) for s in done] == [
        (1, 1, 0), (1, 0, 1), (1, 1, 0), (1, 1, 0)]  # fmt: skip


def test_the_code_fingerprint_names_the_libraries_and_is_computed_once() -> None:
    """numpy, scipy, opencv and mcap by their installed versions; the sources hashed once
    per process (the second call is the cache's)."""
    import numpy
    import scipy

    import fuzzyslam.reproduce.sweep as sw

    code = json.loads(sw.code_fingerprint())
    assert code["libraries"]["numpy"] == numpy.__version__
    assert code["libraries"]["scipy"] == scipy.__version__
    assert code["libraries"]["opencv"] and code["libraries"]["mcap"]
    hits = sw._sources_hash.cache_info().hits
    assert sw.code_fingerprint() == sw.code_fingerprint()
    assert sw._sources_hash.cache_info().hits == hits + 2


def test_a_folder_without_symbolic_links_gets_hard_links_or_one_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On a file system without symbolic links (os.symlink refused, as on FAT) the
    sweep's log links are hard links to the logs, left alone on a rerun; without hard
    links either (another device), one InputError line naming the log."""
    import fuzzyslam.reproduce.sweep as sw

    runs = tmp_path / "runs" / "a"
    runs.mkdir(parents=True)
    (runs / "log.mcap").write_bytes(b"log bytes")
    (runs / "truth.tum").write_text("0 0 0 0 0 0 0 1\n")
    root = tmp_path / "sweep"
    root.mkdir()

    def no_symlinks(*args, **kwargs):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "symlink", no_symlinks)
    logs = [runs / "log.mcap"]
    sw.link_logs(root, logs)
    names = [name for pairs in sw.log_links(logs) for _, name in pairs]
    assert len(names) == 2
    for src, name in (p for pairs in sw.log_links(logs) for p in pairs):
        link = root / name
        assert not link.is_symlink() and os.path.samefile(link, src)
    inode = (root / names[0]).stat().st_ino
    sw.link_logs(root, logs)  # a rerun: the same links
    assert (root / names[0]).stat().st_ino == inode
    assert not list(root.rglob(".*.link"))

    def no_links(*args, **kwargs):
        raise OSError(18, "Invalid cross-device link")

    monkeypatch.setattr(os, "link", no_links)
    (tmp_path / "other").mkdir()
    with pytest.raises(InputError) as info:
        sw.link_logs(tmp_path / "other", logs)
    msg = str(info.value)
    assert "\n" not in msg and "no symbolic links" in msg and str(runs / "log.mcap") in msg


# --- 5: a rerun with another grid replaces the old one -------------------------------


def _tree(root: Path) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*"))


@pytest.mark.slow  # end to end: 4 sweeps in subprocesses (a pool forked in-process can hang)
def test_a_sweep_with_another_grid_replaces_the_old_one(tmp_path: Path) -> None:
    """Rerun into the same OUTDIR: the same grid goes on (every step skipped, nothing
    removed); a grid with fewer values leaves no old grid point (g1/ and g1.yaml of
    wheel_noise 0.02 stayed though the table had one row); another key leaves no old
    figure (sweep_robot.wheel_noise.png stayed beside the new one); fewer seeds leave
    no old seed folder. The cells the new grid has again are kept (skipped)."""
    out = tmp_path / "sw"

    def sweep(*args: str) -> dict:
        p = subprocess.run([sys.executable, "-m", "fuzzyslam", "sweep", str(MICRO), *args,
                            "-o", str(out)], capture_output=True, text=True, timeout=300,
                           env={**os.environ, "MPLBACKEND": "Agg"})  # fmt: skip
        assert p.returncode == 0, p.stderr
        return json.loads(p.stdout)

    first = sweep("--set", "robot.wheel_noise=0.005,0.02", "--seeds", "2")
    assert first["ran"] == 12
    before = _tree(out)
    assert {"g0", "g1", "g0.yaml", "g1.yaml", "g1/seed1"} <= set(before)
    again = sweep("--set", "robot.wheel_noise=0.005,0.02", "--seeds", "2")
    assert again["skipped"] == 12 and _tree(out) == before  # resumed: all kept
    kept = (out / "g0/seed0/eval/metrics.json").read_bytes()

    one = sweep("--set", "robot.wheel_noise=0.005", "--seeds", "1")
    assert one["skipped"] == 3 and one["ran"] == 0  # g0/seed0 reused, not run again
    tree = _tree(out)
    assert not [p for p in tree if p.startswith(("g1", "g0/seed1"))], tree
    assert not [p for p in tree if p.startswith(".sweep/g1") or "seed1" in p], tree
    assert (out / "g0/seed0/eval/metrics.json").read_bytes() == kept
    assert len(json.loads((out / "sweep.json").read_text())["rows"]) == 1

    other = sweep("--set", "slam.calibrate=false,true", "--seeds", "1")
    assert other["figures"] == [str(out / "sweep_slam.calibrate.png")]
    assert sorted(p.name for p in out.glob("sweep_*.png")) == ["sweep_slam.calibrate.png"]
    assert {"g0.yaml", "g1.yaml", "g1/seed0/eval/metrics.json"} <= set(_tree(out))


def test_removing_another_grid_touches_only_the_names_a_sweep_writes(tmp_path: Path) -> None:
    """What a sweep did not write (a note, another PNG, a folder of the user's) stays;
    a log sweep's links of logs no longer swept go, and base.yaml once CONFIG is an
    embedded name."""
    from fuzzyslam.reproduce.plan import Step
    from fuzzyslam.reproduce.sweep import remove_other_grids

    files = ["g0.yaml", "g3.yaml", "g0/seed0/eval/metrics.json", "g0/log1_b/est/x",
             "g3/seed0/log.mcap", "sweep_a.png", "sweep_b.png", "figure.png", "notes.md",
             "mine/g3/x", "g0/mine/x", "logs/log0_a/log.mcap", "logs/log1_b/log.mcap",
             "base.yaml", ".sweep/g0__seed0__log.json", ".sweep/g3__seed0__log.json"]  # fmt: skip
    for f in files:
        (tmp_path / f).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / f).write_text("x")
    step = Step("g0/seed0/log", ("simulate", "g0.yaml", "-o", "g0/seed0/log.mcap"), (), 1.0)
    gone = remove_other_grids(tmp_path, [step], 1, ["seed0"], [tmp_path / "sweep_a.png"],
                              base=False)  # fmt: skip
    assert sorted(p.relative_to(tmp_path).as_posix() for p in gone) == [
        ".sweep/g3__seed0__log.json", "base.yaml", "g0/log1_b", "g3", "g3.yaml",
        "logs/log0_a", "logs/log1_b", "sweep_b.png"]  # fmt: skip
    left = {p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()}
    assert left == {"g0.yaml", "g0/seed0/eval/metrics.json", "figure.png", "notes.md",
                    "mine/g3/x", "g0/mine/x", "sweep_a.png",
                    ".sweep/g0__seed0__log.json"}  # fmt: skip
    assert not (tmp_path / "logs").exists()
