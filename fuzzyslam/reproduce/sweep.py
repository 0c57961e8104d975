"""``fuzzyslam sweep``: a grid of config values x seeds (or x recorded logs).

Each grid point is a config file ``OUTDIR/gI.yaml`` that ``extends`` the base config and
sets the swept keys; each (grid point, seed) is the chain::

    simulate gI.yaml --seed S -> gI/seedS/log.mcap -> run -> gI/seedS/est
                                                    -> evaluate -> gI/seedS/eval

and with recorded logs (``logs``) each (grid point, log J) is::

    run LOG --config gI.yaml -> gI/logJ/est -> evaluate TRUTH -> gI/logJ/eval

where TRUTH is ``truth.tum`` beside the log (evaluated with ``--align``: a real log's map
frame is its start), else the log itself when it holds a ground-truth topic (a simulated
log), else there is no evaluation (the run only). The steps name each log (and its
truth.tum) by a symbolic link in OUTDIR, ``logs/logJ_STEM/NAME`` (:func:`link_logs`),
rewritten on every run: the commands, their outputs (est/summary.json's ``log``,
eval/metrics.json's ``truth``) and the step hashes are the same wherever OUTDIR and the
logs are, and a sweep folder moved or copied elsewhere goes on with its steps skipped.

run by the same engine as ``reproduce`` (local pool or ``--scheduler``), in OUTDIR itself
so that a sweep killed halfway goes on: every finished step leaves a record
``OUTDIR/.sweep/<step>.json`` with a content hash of its command, the config files it
names, the code (:func:`code_fingerprint`: the package's sources and the versions of the
libraries its numbers come from) and its dependencies' hashes (a chain, so a changed
config reaches every step after it). A step whose hash is unchanged and whose output
exists is skipped and counted; a log's hash is that of its bytes (and of its truth.tum),
not of its path. The table
(``sweep.md``, ``sweep.json``) gives, per grid point, the mean, sample standard deviation,
min and max over seeds (or logs) of the evaluation's errors, and one figure per swept key
(``sweep_KEY.png``, reproduce/sweep_plot.py) draws them against the key's values.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib.metadata
import itertools
import json
import math
import os
import re
import shutil
from pathlib import Path
from typing import Any

from fuzzyslam import __version__
from fuzzyslam.config import config_layers
from fuzzyslam.errors import InputError
from fuzzyslam.fileio import atomic_path
from fuzzyslam.reproduce.execute import StepResult, execute
from fuzzyslam.reproduce.overrides import check_grid, override_text
from fuzzyslam.reproduce.plan import Step, _topological

# The folder of OUTDIR holding a link to each recorded log (and its truth.tum): what the
# steps name (:func:`link_logs`)
LINKS = "logs"

# The package whose sources are part of every step's hash (:func:`code_fingerprint`)
PACKAGE_DIR = Path(__file__).resolve().parents[1]
# The libraries whose versions are part of it: the distributions that may provide each
# (the first installed counts)
LIBRARIES = {
    "numpy": ("numpy",),
    "scipy": ("scipy",),
    "opencv": ("opencv-python", "opencv-python-headless", "opencv-contrib-python",
               "opencv-contrib-python-headless"),
    "mcap": ("mcap",),
}  # fmt: skip

# (name, path in metrics.json's phases.overall, scale, unit)
MEASURES = (
    ("mean position error", ("position_m", "mean"), 100.0, "cm"),
    ("max position error", ("position_m", "max"), 100.0, "cm"),
    ("mean heading error", ("heading_deg", "mean"), 1.0, "deg"),
)


def check_base(config: str, outdir: Path) -> None:
    """Refuse a base config a sweep cannot use (one line naming it): a file that
    ``extends`` a file of its own (copied to ``OUTDIR/base.yaml``, it would not find it;
    an embedded config is fine), or a grid point's config of the sweep in ``outdir``
    (``gI.yaml``, which the sweep rewrites).

    Parameters
    ----------
    config : str
        The base config: a YAML file or an embedded name.
    outdir : Path
        The sweep's output directory.
    """
    _, chain = config_layers(config)
    if not Path(config).is_file():
        return
    local = [c for c in chain[1:] if not c.startswith("<embedded ")]
    if local:
        raise InputError(
            config,
            f"extends the file {local[0]}: a sweep's CONFIG may extend embedded configs "
            "only (it is copied to OUTDIR/base.yaml); merge the files into one",
        )
    path = Path(config).resolve()
    if path.parent == outdir.resolve() and re.fullmatch(r"g\d+\.yaml", path.name):
        raise InputError(
            config, "is a grid point's config of this sweep's OUTDIR, which it rewrites; "
            "copy it elsewhere first",
        )  # fmt: skip


def check_outdir(outdir: Path) -> None:
    """Raise InputError (one line) unless ``outdir`` is absent, empty or a previous sweep
    output (it holds ``.sweep/``), which the sweep goes on with.

    Parameters
    ----------
    outdir : Path
        The sweep's output directory.
    """
    if not outdir.is_dir() or not any(outdir.iterdir()):
        return
    if not (outdir / ".sweep").is_dir():
        raise InputError(
            outdir,
            "exists and is not a sweep output (no .sweep/ folder); refusing to write into "
            "it: remove it or choose another -o",
        )


def grid_configs(
    config: str, sets: list[tuple[str, list[Any]]], outdir: Path
) -> list[tuple[str, dict[str, Any]]]:
    """Write ``gI.yaml`` per grid point into ``outdir`` (and ``base.yaml``, a copy of a
    config file), each only when its text changed; return [(file name, {key: value})].
    Call :func:`~fuzzyslam.reproduce.overrides.check_grid` first: nothing is loaded
    here."""
    base = config
    if Path(config).is_file():
        text = Path(config).read_text(encoding="utf-8")
        base_file = outdir / "base.yaml"
        if not base_file.is_file() or base_file.read_text(encoding="utf-8") != text:
            shutil.copyfile(config, base_file)
        base = "base.yaml"
    points = []
    for i, overrides in enumerate(grid_points(sets)):
        name = f"g{i}.yaml"
        text = override_text(base, overrides, f"sweep grid point {i}: {overrides}")
        path = outdir / name
        if not path.is_file() or path.read_text(encoding="utf-8") != text:
            path.write_text(text, encoding="utf-8")
        points.append((name, overrides))
    return points


def grid_points(sets: list[tuple[str, list[Any]]]) -> list[dict[str, Any]]:
    """The grid: {key: value} of each point, the product of the keys' values.

    Parameters
    ----------
    sets : list of (str, list)
        Dotted keys and their values.

    Returns
    -------
    list of dict
    """
    keys = [k for k, _ in sets]
    return [dict(zip(keys, values, strict=True))
            for values in itertools.product(*(v for _, v in sets))]  # fmt: skip


def sweep_steps(points: list[tuple[str, dict]], seeds: list[int]) -> list[Step]:
    """simulate -> run -> evaluate for every grid point and seed."""
    steps = []
    for i, (cfg, values) in enumerate(points):
        for s in seeds:
            d = f"g{i}/seed{s}"
            label = point_label(values, f"seed {s}")  # the figures' titles
            steps += [
                Step(f"{d}/log", ("simulate", cfg, "-o", f"{d}/log.mcap", "--seed", str(s)),
                     (), 16.0, "simulate",
                     (("config", cfg), ("output", f"{d}/log.mcap"), ("seed", s))),
                Step(f"{d}/est", ("run", f"{d}/log.mcap", "-o", f"{d}/est", "--config", cfg),
                     (f"{d}/log",), 4.0, "run",
                     (("log", f"{d}/log.mcap"), ("outdir", f"{d}/est"), ("config", cfg))),
                Step(f"{d}/eval", ("evaluate", f"{d}/log.mcap", f"{d}/est", "-o", f"{d}/eval",
                                   "--label", label),
                     (f"{d}/log", f"{d}/est"), 5.0, "evaluate",
                     (("truth", f"{d}/log.mcap"), ("estimate", f"{d}/est"),
                      ("outdir", f"{d}/eval"), ("label", label))),
            ]  # fmt: skip
    return steps


def point_label(values: dict, unit: str) -> str:
    """A run's label in its evaluation's figures: the grid point's values and the seed or
    log (``robot.wheel_noise=0.005, seed 1``).

    Parameters
    ----------
    values : dict
        The grid point (key -> value).
    unit : str
        The seed or log.

    Returns
    -------
    str
    """
    return ", ".join([*(f"{k}={v}" for k, v in values.items()), unit])


def log_units(logs: list[Path]) -> list[str]:
    """Directory names of the logs in a sweep: ``logJ_STEM`` (J its place in ``logs``), or
    ``logJ_DIR_STEM`` when two logs have the same file name (``runs/*/log.mcap``)."""
    clash = len({p.stem for p in logs}) < len(logs)
    names = [f"{p.parent.name}_{p.stem}" if clash else p.stem for p in logs]
    return [f"log{j}_{re.sub(r'[^A-Za-z0-9_.-]', '_', n)}" for j, n in enumerate(names)]


def log_links(logs: list[Path]) -> list[tuple[tuple[Path, str], ...]]:
    """The links of :func:`link_logs`: per log, (file, its link relative to OUTDIR) of
    the log and, when there is one, of the ``truth.tum`` beside it (second):
    ``logs/logJ_STEM/NAME`` and ``logs/logJ_STEM/truth.tum``.

    Parameters
    ----------
    logs : list of Path
        The recorded logs.

    Returns
    -------
    list of tuple
    """
    out = []
    for log, unit in zip(logs, log_units(logs), strict=True):
        d = f"{LINKS}/{unit}"
        tum = log.parent / "truth.tum"
        out.append(((log, f"{d}/{log.name}"),
                    *([(tum, f"{d}/truth.tum")] if tum.is_file() else [])))  # fmt: skip
    return out


def relative_to_outdir(path: Path, root: Path) -> str:
    """``path`` as OUTDIR ``root`` names it: relative to it when the two share a folder
    other than ``/`` (``../runs/a/log.mcap``: the same wherever the tree that holds both
    sits, or is mounted), else absolute.

    Parameters
    ----------
    path, root : Path
        A file, and the sweep's output directory.

    Returns
    -------
    str
    """
    path, root = Path(os.path.realpath(path)), Path(os.path.realpath(root))
    if os.path.commonpath([path, root]) == root.anchor:
        return str(path)
    return os.path.relpath(path, root)


def link_logs(root: Path, logs: list[Path]) -> None:
    """Make (or point again) the links the steps name, :func:`log_links`, in ``root``.

    A link's target is relative when the log and ``root`` share a folder other than
    ``/`` (:func:`relative_to_outdir`), else absolute: with ``--scheduler`` (a shared
    filesystem) the workers, which run each step in ``root`` at its absolute path, find
    the log as the client does; with ``--ship-files`` the client reads the log through
    its link and sends its bytes under the link's name. A moved sweep folder gets its
    links pointed again on its next run; the steps' commands do not change. On a file
    system without symbolic links (FAT, exFAT, some SMB mounts) a link is a hard link
    to the log; without either, InputError (one line) says so.

    Parameters
    ----------
    root : Path
        The sweep's output directory (it exists).
    logs : list of Path
        The recorded logs.
    """
    for pairs in log_links(logs):
        for src, name in pairs:
            link = root / name
            link.parent.mkdir(parents=True, exist_ok=True)
            target = relative_to_outdir(src, link.parent)
            if link.is_symlink() and os.readlink(link) == target:
                continue
            if not link.is_symlink() and link.exists() and os.path.samefile(link, src):
                continue  # a hard link to the log (below)
            tmp = link.with_name(f".{link.name}.link")
            tmp.unlink(missing_ok=True)
            try:
                os.symlink(target, tmp)
            except OSError:  # no symbolic links here: a hard link, on the same device
                try:
                    os.link(src, tmp)
                except OSError as exc:
                    raise InputError(
                        root,
                        f"cannot link the log {src} into the sweep folder: its file "
                        f"system has no symbolic links and the log is not on it for a "
                        f"hard link ({exc.strerror}); write the sweep elsewhere",
                    ) from None
            os.replace(tmp, link)


def log_steps(points: list[tuple[str, dict]], logs: list[Path], truth_topic: str) -> list[Step]:
    """run (+ evaluate when there is a truth) of every recorded log for every grid point,
    each naming the log and its truth by their links in OUTDIR (:func:`log_links`).

    Parameters
    ----------
    points : list of (str, dict)
        The grid (``grid_configs``).
    logs : list of Path
        Absolute paths of the recorded logs.
    truth_topic : str
        The ground-truth topic of a simulated log (``topics.ground_truth``).

    Returns
    -------
    list of Step
        Per grid point and log: ``gI/logJ_STEM/est`` and, with a truth, ``.../eval``.
    """
    from fuzzyslam.streams.reader import LogReader

    links = log_links(logs)
    truths: list[tuple[str, ...] | None] = []
    for log, pairs in zip(logs, links, strict=True):
        if len(pairs) > 1:  # truth.tum beside the log
            truths.append((pairs[1][1], "--align"))
        elif LogReader(log).counts.get(truth_topic, 0) > 0:
            truths.append((pairs[0][1],))
        else:
            truths.append(None)
    steps = []
    for i, (cfg, values) in enumerate(points):
        for log, unit, pairs, truth in zip(logs, log_units(logs), links, truths, strict=True):
            d = f"g{i}/{unit}"
            name = pairs[0][1]
            run_call = (("log", name), ("outdir", f"{d}/est"), ("config", cfg))
            steps.append(Step(f"{d}/est", ("run", name, "-o", f"{d}/est", "--config", cfg),
                              (), 4.0, "run", run_call))  # fmt: skip
            if truth is not None:
                label = point_label(values, log.name if log.name != "log.mcap" else unit)
                argv = ("evaluate", truth[0], f"{d}/est", "-o", f"{d}/eval", *truth[1:],
                        "--label", label)  # fmt: skip
                call = (("truth", truth[0]), ("estimate", f"{d}/est"), ("outdir", f"{d}/eval"),
                        ("label", label))  # fmt: skip
                if "--align" in truth:
                    call += (("align", True),)
                steps.append(Step(f"{d}/eval", argv, (f"{d}/est",), 5.0, "evaluate", call))
    return steps


@functools.cache
def _sources_hash(package_dir: Path) -> str:
    """SHA-256 of the ``.py`` files under ``package_dir`` (names and bytes, in name
    order) and of the embedded configs (``fuzzyslam.configs``: a grid point may extend
    one by name)."""
    from importlib import resources

    h = hashlib.sha256()
    for f in sorted(package_dir.rglob("*.py")):
        h.update(f.relative_to(package_dir).as_posix().encode() + b"\0")
        h.update(hashlib.sha256(f.read_bytes()).digest())
    configs = resources.files("fuzzyslam.configs")
    for c in sorted((c for c in configs.iterdir() if c.name.endswith(".yaml")),
                    key=lambda c: c.name):  # fmt: skip
        h.update(f"configs/{c.name}".encode() + b"\0")
        h.update(hashlib.sha256(c.read_bytes()).digest())
    return h.hexdigest()


def _library_version(names: tuple[str, ...]) -> str | None:
    """The version of the first installed distribution of ``names``, or None."""
    for name in names:
        try:
            return importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            continue
    return None


@functools.cache
def _library_versions() -> dict[str, str | None]:
    """The version of each of :data:`LIBRARIES` (None: not installed), once a process."""
    return {lib: _library_version(names) for lib, names in LIBRARIES.items()}


def code_fingerprint() -> str:
    """What the code part of a step's hash is: the fuzzyslam version, a hash of the
    package's sources (its ``.py`` files' bytes under :data:`PACKAGE_DIR`, and the
    embedded configs) and the versions of numpy, scipy, opencv and mcap, as JSON. So
    an edited source file (an editable install keeps its version number) or an
    upgraded library runs every step again instead of reusing results of other code.

    Computed once per process and package folder, in 10-30 ms (measured 2026-12-03 on
    this 2-core machine under load: 6-19 ms to hash the package's 147 files, 1.5 MB,
    and 6-16 ms for the versions, read from the installed distributions' metadata
    without importing the libraries), against seconds for any step.

    Returns
    -------
    str
    """
    return json.dumps({"fuzzyslam": __version__, "sources": _sources_hash(PACKAGE_DIR),
                       "libraries": _library_versions()}, sort_keys=True)  # fmt: skip


def _is_input(arg: str) -> bool:
    """Whether a step's argument names a recorded input: a link of :data:`LINKS` (or an
    absolute path), whose bytes, not its path, go into the step's hash."""
    return arg.startswith(f"{LINKS}/") or os.path.isabs(arg)


def step_hashes(steps: list[Step], root: Path) -> dict[str, str]:
    """Content hash of each step: its command, the text of the config files it names,
    the bytes of the recorded inputs it names (logs and truths, through their links in
    ``LINKS``), the code (:func:`code_fingerprint`) and the hashes of its dependencies.
    Nothing in it depends on where ``root`` or the logs are.

    Parameters
    ----------
    steps : list of Step
        The sweep's steps.
    root : Path
        The sweep's output directory (the steps' working directory).

    Returns
    -------
    dict
        Step key -> hex digest.
    """
    out: dict[str, str] = {}
    files: dict[str, str] = {}
    code = code_fingerprint()
    for s in _topological(steps):
        h = hashlib.sha256()
        h.update(json.dumps([code, list(s.argv)]).encode())
        for a in s.argv:
            if a.endswith(".yaml") and (root / a).is_file():
                h.update((root / a).read_bytes())
                if (root / "base.yaml").is_file():
                    h.update((root / "base.yaml").read_bytes())
            elif _is_input(a) and (root / a).is_file():
                real = os.path.realpath(root / a)
                if real not in files:
                    with open(real, "rb") as f:
                        files[real] = hashlib.file_digest(f, "sha256").hexdigest()
                h.update(files[real].encode())
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
    logs: list[str | os.PathLike] | None = None,
    ship: bool = False,
) -> dict[str, Any]:
    """Run the grid x seeds (or x recorded logs) into ``outdir`` (resumable); return the
    stdout summary.

    Parameters
    ----------
    config : str
        Base config: a YAML file or an embedded name.
    sets : list of (str, list)
        Swept keys (dotted config paths) and their values; the grid is their product.
    seeds : list of int
        Seeds of every grid point (ignored with ``logs``).
    outdir : path
        Output directory; kept between runs (its finished steps are skipped). It must be
        absent, empty or a previous sweep's output (it holds ``.sweep/``); once this
        sweep has written its table, what a previous one made and this grid has not
        (other grid points, seeds, logs, figures) is removed
        (:func:`remove_other_grids`).
    jobs, scheduler
        As for ``reproduce``.
    logs : list of path or None
        Recorded logs: each is run (and evaluated, given a truth) at every grid point
        instead of simulating seeds; the steps name them by their links in
        ``OUTDIR/logs/`` (:func:`link_logs`), and sweep.json by their paths relative to
        OUTDIR (:func:`relative_to_outdir`, as a CONFIG file), so that the same sweep
        elsewhere writes the same files (timing fields aside).
    ship : bool
        Send the steps' files with their tasks (workers without a shared filesystem).

    Returns
    -------
    dict
        The stdout summary: table and figure paths, steps run and skipped, the table.
    """
    root = Path(outdir)
    if not sets:
        raise InputError(root, "nothing to sweep: give --set KEY=V1,V2,...")
    if root.exists() and not root.is_dir():
        raise InputError(root, "output path exists and is not a directory")
    if not root.resolve().parent.is_dir():
        raise InputError(root, f"parent directory {root.resolve().parent} does not exist")
    # every input is checked before anything is written: nothing is left on an error
    check_base(config, root)
    configs = check_grid(config, sets)
    check_outdir(root)
    points = [(f"g{i}.yaml", p) for i, p in enumerate(grid_points(sets))]
    if logs:
        log_paths = [Path(p).resolve() for p in logs]
        units = log_units(log_paths)
        steps = log_steps(points, log_paths, configs[0].topics.ground_truth)
    else:
        units = [f"seed{s}" for s in seeds]
        steps = sweep_steps(points, seeds)
    (root / ".sweep").mkdir(parents=True, exist_ok=True)
    grid_configs(config, sets, root)  # the files the steps name: the same points
    if logs:
        link_logs(root, log_paths)
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
        execute(todo, root, jobs, label="sweep", scheduler=scheduler, on_done=remember,
                ship=ship)  # fmt: skip
    rows = [_row(root, i, overrides, units) for i, (_, overrides) in enumerate(points)]
    shown = relative_to_outdir(Path(config), root) if Path(config).is_file() else config
    info = {"config": shown, "sets": [[k, v] for k, v in sets], "seeds": [] if logs else seeds,
            "logs": [relative_to_outdir(p, root) for p in log_paths] if logs else [],
            "steps": len(steps), "ran": len(todo), "skipped": len(skipped)}  # fmt: skip
    text = json.dumps({"info": info, "rows": rows}, indent=2, sort_keys=True, default=str)
    with atomic_path(root / "sweep.json") as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    _write_table(root / "sweep.md", rows, info)
    from fuzzyslam.reproduce.sweep_plot import plot_sweep

    figures = plot_sweep(root, rows, [k for k, _ in sets], len(units),
                         "logs" if logs else "seeds")  # fmt: skip
    # a changed grid replaces the old one: its other points, seeds and figures go
    remove_other_grids(root, steps, len(points), units, figures, Path(config).is_file())
    return {"command": "sweep", "table": str(root / "sweep.md"),
            "results": str(root / "sweep.json"), "figures": [str(f) for f in figures],
            **info, "rows": rows}  # fmt: skip


def remove_other_grids(
    root: Path, steps: list[Step], n_points: int, units: list[str], figures: list[Path],
    base: bool,
) -> list[Path]:  # fmt: skip
    """Remove what a previous sweep in ``root`` made and this one did not: the grid
    points beyond this grid's (``gI/``, ``gI.yaml``), the seeds' or logs' folders of a
    grid point that this sweep has not (``gI/seedS/``, ``gI/logJ_NAME/``), their links
    (``logs/logJ_NAME/``), the figures of keys no longer swept (``sweep_KEY.png``), the
    step records of steps not in this sweep (``.sweep/``) and ``base.yaml`` when CONFIG
    is no file now. Called once the sweep has written its table: OUTDIR then holds this
    grid's outputs only (a changed grid replaces the old one), and a sweep stopped
    before leaves the old ones for a rerun to go on with. Only the names a sweep writes
    are touched; the cells this grid has again stay (their steps were skipped or run).

    Parameters
    ----------
    root : Path
        The sweep's output directory.
    steps : list of Step
        This sweep's steps (all of them, skipped or run).
    n_points : int
        This grid's points (``g0`` .. ``g{n_points - 1}``).
    units : list of str
        This sweep's seed or log folder names (``seedS``, ``logJ_NAME``).
    figures : list of Path
        The figures this sweep drew.
    base : bool
        Whether this sweep's grid points extend ``base.yaml`` (CONFIG is a file).

    Returns
    -------
    list of Path
        What was removed.
    """
    gone: list[Path] = []

    def remove(p: Path) -> None:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)
        gone.append(p)

    keep_units = set(units)
    unit_name = re.compile(r"seed\d+|log\d+_.+")
    drawn = {f.name for f in figures}
    for p in sorted(root.iterdir()):
        point = re.fullmatch(r"g(\d+)(\.yaml)?", p.name)
        if point is not None and int(point.group(1)) >= n_points:
            remove(p)
        elif point is not None and point.group(2) is None and p.is_dir():
            for cell in sorted(p.iterdir()):
                if unit_name.fullmatch(cell.name) and cell.name not in keep_units:
                    remove(cell)
        elif re.fullmatch(r"sweep_.+\.png", p.name) and p.name not in drawn:
            remove(p)
        elif p.name == "base.yaml" and not base:
            remove(p)
    links = root / LINKS
    if links.is_dir() and not links.is_symlink():
        for d in sorted(links.iterdir()):
            if unit_name.fullmatch(d.name) and d.name not in keep_units:
                remove(d)
        if not any(links.iterdir()):
            links.rmdir()
    records = {_record(root, s.key).name for s in steps}
    for rec in sorted((root / ".sweep").glob("*.json")):
        if rec.name not in records:
            remove(rec)
    return gone


def _row(root: Path, i: int, overrides: dict[str, Any], units: list[str]) -> dict[str, Any]:
    """One grid point: each run's measures (``runs``, unit -> measure -> value; a log
    without an evaluation is absent) and their statistics (``measures``)."""
    runs: dict[str, dict[str, float | None]] = {}
    for u in units:
        path = root / f"g{i}/{u}/eval/metrics.json"
        if not path.is_file():
            continue
        overall = json.loads(path.read_text(encoding="utf-8"))["phases"]["overall"]
        runs[u] = {}
        for name, (a, b), scale, unit in MEASURES:
            v = overall.get(a, {}).get(b)
            runs[u][f"{name} ({unit})"] = None if v is None else scale * v
    measures = {}
    for name, _, _, unit in MEASURES:
        m = f"{name} ({unit})"
        measures[m] = _stats([r[m] for r in runs.values() if r[m] is not None])
    return {"point": i, "values": overrides, "measures": measures, "runs": runs}


def _fmt(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def _write_table(path: Path, rows: list[dict], info: dict) -> None:
    keys = [k for k, _ in info["sets"]]
    measures = list(rows[0]["measures"]) if rows else []
    head = [*keys, *(f"{m}: mean, sd [min, max]" for m in measures)]
    over = (f"Seeds {', '.join(map(str, info['seeds']))}" if info["seeds"] else
            f"{len(info['logs'])} recorded logs")  # fmt: skip
    truth = ("the truth beside each log (truth.tum, aligned) or in it" if info["logs"] else
             "the simulator's ground truth")  # fmt: skip
    lines = [
        f"# Sweep of {info['config']}",
        "",
        f"{over}; {info['steps']} steps, {info['ran']} run, {info['skipped']} skipped "
        f"(unchanged). Errors over the whole log against {truth}.",
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
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
