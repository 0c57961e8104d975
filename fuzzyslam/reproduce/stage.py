"""``fuzzyslam reproduce``: the paper's experiment over seeds, from the embedded configs.

Builds the plan (:mod:`~fuzzyslam.reproduce.plan`), runs it in a temporary directory
beside OUTDIR (:mod:`~fuzzyslam.reproduce.execute`), reads every evaluation's
metrics.json, aggregates the table (:mod:`~fuzzyslam.reproduce.table`), writes the
report (:mod:`~fuzzyslam.reproduce.report`) and moves the whole tree into OUTDIR only
when everything succeeded. A previous reproduce output in OUTDIR is replaced whole (no
old seed folder survives); any other non-empty directory is refused.
"""

from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import fields
from pathlib import Path
from typing import Any

from fuzzyslam import __version__
from fuzzyslam.config import Config
from fuzzyslam.errors import InputError
from fuzzyslam.fileio import OutputDir, _in_place_only
from fuzzyslam.reproduce.execute import StepResult, execute
from fuzzyslam.reproduce.overrides import check_suite, set_options, suite_with
from fuzzyslam.reproduce.plan import FULL, QUICK, Suite, build_plan, evaluations
from fuzzyslam.reproduce.report import (
    RunInfo,
    StepRecord,
    draw_summary,
    summary_inputs,
    write_commands,
    write_report,
    write_results,
)
from fuzzyslam.reproduce.table import SeedResult, aggregate, headline_key, run_labels


def suite_configs(suite: Suite, root: Path) -> dict[str, Config]:
    """The loaded config of each log of the suite (embedded names, or files in ``root``:
    ``--set``), by log name (paper, bumps, dark, people)."""
    from fuzzyslam.config import load_config

    names = {f.name: getattr(suite, f.name) for f in fields(suite)}
    return {
        log: load_config(str(root / n) if (root / n).is_file() else n) for log, n in names.items()
    }


def calibration_truth(configs: dict[str, Config]) -> dict[str, list[float]]:
    """The simulator's true wheel factors of each log of the table's calibration rows
    (paper, bumps) whose config calibrates the odometry (``slam.calibrate``): its
    ``robot.left_scale``, ``right_scale``, ``base_scale`` (``SeedResult.calibration_truth``).

    Parameters
    ----------
    configs : dict
        :func:`suite_configs`.

    Returns
    -------
    dict
        Log name -> [s_L, s_R, s_B].
    """
    from fuzzyslam.slam.calibration import true_factors

    return {
        log: [float(v) for v in true_factors(configs[log].robot)]
        for log in ("paper", "bumps")
        if configs[log].slam.calibrate
    }


def seed_result(
    root: Path,
    seed: int,
    done: dict[str, StepResult],
    beyond: bool = True,
    kinds: dict[str, str] | None = None,
    truth: dict[str, list[float]] | None = None,
) -> SeedResult:
    """The evaluations' metrics and the runs' and maps' summaries of one seed; ``kinds``:
    each step's kind (``Step.kind``) by key (default: told from the summaries);
    ``truth``: :func:`calibration_truth`."""
    d = f"seed{seed}"
    evals = {}
    for name in evaluations(beyond):
        p = root / d / f"eval_{name}" / "metrics.json"
        evals[name] = json.loads(p.read_text(encoding="utf-8"))
    mine = {k.split("/", 1)[1]: r.summary for k, r in done.items() if k.startswith(f"{d}/")}
    if kinds is not None:
        kind = {k.split("/", 1)[1]: v for k, v in kinds.items() if k.startswith(f"{d}/")}
        runs = {k: v for k, v in mine.items() if v is not None and kind.get(k) == "run"}
        maps = {k: v for k, v in mine.items() if v is not None and kind.get(k) == "map"}
    else:
        runs = {k: v for k, v in mine.items() if v and v.get("command") == "run"}
        maps = {k: v for k, v in mine.items() if v and "reference_truth" in v}
    seconds = sum(r.seconds for k, r in done.items() if k.startswith(f"{d}/"))
    return SeedResult(seed, evals, runs, maps, seconds, dict(truth or {}))


class SummaryDrawing:
    """summary.png (:func:`~fuzzyslam.reproduce.report.draw_summary`) drawn in a thread of
    the parent as soon as the steps whose files it reads are done, while the last steps
    (the evaluations) run in the workers, instead of after them: the parent only waits
    for the workers meanwhile, and the picture is the same (its inputs are finished
    files). ``step_done`` is execute's ``on_done``; ``result`` waits for the picture.

    Parameters
    ----------
    root : Path
        The (temporary) output directory.
    seed_dir : str
        The seed drawn ("seed0").
    keys : set of str
        The plan's step keys.
    """

    def __init__(self, root: Path, seed_dir: str, keys: set[str]) -> None:
        self.root, self.seed_dir = root, seed_dir
        self.waiting = summary_inputs(seed_dir) & keys
        self.thread: threading.Thread | None = None
        self.drawn = False
        self.error: BaseException | None = None  # no thread before the pool forks

    def _draw(self) -> None:
        try:
            self.drawn = draw_summary(self.root, self.seed_dir, self.root / "summary.png")
        except BaseException as exc:  # raised again by result(), in the parent's thread
            self.error = exc

    def _start(self) -> None:
        self.thread = threading.Thread(target=self._draw, name="summary.png", daemon=True)
        self.thread.start()

    def step_done(self, step: Any, _result: Any) -> None:
        """Execute's ``on_done``: start drawing when the last input is done."""
        if self.thread is None and self.waiting and step.key in self.waiting:
            self.waiting.discard(step.key)
            if not self.waiting:
                self._start()

    def join(self) -> None:
        """Wait for the drawing, if it started."""
        if self.thread is not None:
            self.thread.join()

    def result(self) -> bool:
        """Whether summary.png was drawn (every step done: started now if it was not)."""
        if self.thread is None:
            self._start()
        self.join()
        if self.error is not None:
            raise self.error
        return self.drawn


# Files that mark a directory as a reproduce output (which a rerun may replace whole).
MARKERS = ("results.json", "commands.sh")


def check_outdir(outdir: Path) -> None:
    """Raise InputError (one line) unless ``outdir`` is absent, empty or a previous
    reproduce output that can be replaced whole (not the working directory)."""
    if not outdir.is_dir() or not any(outdir.iterdir()):
        return
    if not any((outdir / m).is_file() for m in MARKERS):
        raise InputError(
            outdir,
            "exists and is not a reproduce output (no results.json); "
            "refusing to replace it: remove it or choose another -o",
        )
    if _in_place_only(outdir.resolve()):
        raise InputError(
            outdir,
            "is the working directory (or holds it) and cannot be "
            "replaced whole; refusing: run from elsewhere or choose another -o",
        )


def reproduce(
    outdir: str | os.PathLike,
    seeds: list[int],
    quick: bool = False,
    jobs: int | None = None,
    beyond: bool = True,
    scheduler: str | None = None,
    keep_logs: bool | None = None,
    ship: bool = False,
    overrides: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Run the experiment for ``seeds`` into ``outdir``; return the stdout summary.

    Parameters
    ----------
    outdir : path
        Output directory; a previous reproduce output there is replaced whole.
    seeds : list of int
        The seeds.
    quick : bool
        The two-run scenarios (quick_*.yaml).
    jobs : int or None
        Steps at once (default: the cores, or the Dask cluster's worker threads).
    beyond : bool
        False: the paper's phases A-D only.
    scheduler : str or None
        Address of an existing Dask scheduler that runs the steps (shared filesystem).
    keep_logs : bool or None
        Keep the simulated MCAP logs (44 MB each on the full scenario); default: only for
        one seed.
    ship : bool
        Send the steps' files with their tasks (workers without a shared filesystem).
    overrides : dict or None
        Config keys (dotted) and values set in every config of the suite (``--set``):
        the steps name ``set_NAME.yaml`` files in OUTDIR that extend the embedded ones
        (reproduce/overrides.py).

    Returns
    -------
    dict
        The stdout summary.
    """
    if not seeds:
        raise InputError(outdir, "no seeds to run")
    overrides = dict(overrides or {})
    if keep_logs is None:
        keep_logs = len(seeds) == 1
    t0 = time.perf_counter()
    check_suite(QUICK if quick else FULL, overrides)  # --set: one line, nothing written
    check_outdir(Path(outdir))
    with OutputDir(outdir, owns=("*",)) as tmp:
        suite = suite_with(QUICK if quick else FULL, overrides, tmp)
        configs = suite_configs(suite, tmp)
        truth = calibration_truth(configs)
        calibrated = frozenset(log for log, c in configs.items() if c.slam.calibrate)
        steps = build_plan(seeds, suite, beyond, calibrated)
        for s in seeds:
            (tmp / f"seed{s}").mkdir()
        write_commands(tmp / "commands.sh", steps, set_options(overrides))
        summary = SummaryDrawing(tmp, f"seed{seeds[0]}", {st.key for st in steps})
        ran: dict[str, Any] = {}
        try:
            done = execute(steps, tmp, jobs, scheduler=scheduler, final=Path(outdir),
                           ship=ship, on_done=summary.step_done, engine_info=ran)  # fmt: skip
            drawn = summary.result()
        finally:
            summary.join()  # before a failure removes the directory it writes into
        workers = sorted({r.worker for r in done.values()})
        kinds = {st.key: st.kind for st in steps}
        results = [seed_result(tmp, s, done, beyond, kinds, truth) for s in seeds]
        aggs = aggregate(results)
        png = "summary.png" if drawn else None
        info = RunInfo(
            command="fuzzyslam reproduce"
            + (" --quick" if quick else "")
            + f" --seeds {len(seeds)}"
            + ("" if beyond else " --paper-only")
            + set_options(overrides),
            suite="quick" if quick else "paper",
            configs=[suite.paper, suite.bumps] + ([suite.dark, suite.people] if beyond else []),
            overrides=overrides,
            seeds=seeds,
            jobs=ran["jobs"],  # steps at once: not the workers that ran one (a lost
            # worker's replacement is one more of those, never one more step at once)
            engine=f"dask {scheduler}" if scheduler else "local",
            workers=workers,
            logs_kept=keep_logs,
            steps=len(steps),
            version=__version__,
            wall_s=time.perf_counter() - t0,
        )
        step_log = [
            StepRecord(key=s.key, command=s.command, seconds=round(done[s.key].seconds, 2),
                       stderr=done[s.key].stderr, worker=done[s.key].worker,
                       pid=done[s.key].pid)
            for s in steps
        ]  # fmt: skip
        write_results(tmp / "results.json", aggs, results, info, step_log)
        write_report(tmp / "report.md", aggs, results, seeds, info, png, beyond)
        if not keep_logs:  # read by the steps and draw_summary only
            for log in tmp.glob("seed*/*.mcap"):
                log.unlink()
    labels = run_labels(results[0])
    headline = {headline_key(a.row, labels): a.mean for a in aggs}  # keys end with the unit
    out = Path(outdir)
    return {
        "command": "reproduce",
        "report": str(out / "report.md"),
        "results": str(out / "results.json"),
        "commands": str(out / "commands.sh"),
        "seeds": seeds,
        "suite": info.suite,
        "wall_time_s": round(info.wall_s, 1),
        "headline": headline,
    }


run = reproduce  # the stage convention: every stage package's entry is ``stage.run``
