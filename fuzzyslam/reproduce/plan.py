"""The paper's experiment as a graph of stage commands (pure: no I/O).

Each :class:`Step` is one ``fuzzyslam`` command line with paths relative to the
reproduce output directory, the steps it needs first, and an expected cost (for
scheduling and progress). Per seed the graph is, in docs/experiment.md's terms::

    paper.mcap  --run-->        AB       (phases A and B: lamps only, no help)
                --map(AB)-->    fgm      (FGM frozen at the end of the freeze run)
                --run --map-->  C        (phase C: heading fixes, the paper)
                --run --map-->  C_pose   (beyond: full-pose fixes)
    bumps.mcap  --run --map fgm --fix-from 0-->  D   (phase D: a bump each run)
    dark.mcap   --run--> dark_none, --map--> dark_fgm, --run --map--> dark_heading, dark_pose
    people.mcap --run--> people_none, --map--> people_fgm, --run --map --fix pose--> people_pose

and every estimate is evaluated against its log's ground truth. Phase D borrows the
map of the paper log: with a 10-degree bump in every run, the bump log's own phase A
is lost at its first bump (lamps alone cannot recover a heading jump they never saw).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from typing import Any

from fuzzyslam.stamps import LogTime


@dataclass(frozen=True)
class Suite:
    """The embedded configs of one experiment: the paper's, or its two-run version."""

    paper: str
    bumps: str
    dark: str
    people: str


FULL = Suite("paper.yaml", "paper_bumps.yaml", "paper_dark.yaml", "paper_people.yaml")
QUICK = Suite("quick_failures.yaml", "quick_bumps.yaml", "quick_dark.yaml", "quick_people.yaml")


@dataclass(frozen=True)
class Step:
    """One ``fuzzyslam`` command of the experiment."""

    key: str  # unique: "seed0/C"
    argv: tuple[str, ...]  # arguments after ``fuzzyslam``
    deps: tuple[str, ...] = ()
    cost: float = 1.0  # expected seconds (full scenario), for scheduling and progress
    kind: str = field(default="")  # simulate | run | map | evaluate
    # the same step as a call of the stage's entry: fuzzyslam.<package>.stage.run(**call)
    call: tuple[tuple[str, Any], ...] = ()

    @property
    def command(self) -> str:
        """The shell form of the step."""
        return "fuzzyslam " + shlex.join(self.argv)


# Evaluations drawn in the report, per seed: key -> (log, estimate dir, map dir, label)
EVALUATIONS: dict[str, tuple[str, str, str, str]] = {
    "AB": ("paper", "AB", "fgm", "A+B: lamps only"),
    "C": ("paper", "C", "fgm", "C: heading fixes (paper)"),
    "C_pose": ("paper", "C_pose", "fgm", "C: pose fixes (beyond)"),
    "D": ("bumps", "D", "fgm", "D: bumps, heading fixes"),
    "dark_none": ("dark", "dark_none", "dark_fgm", "all lamps off: no fixes"),
    "dark_heading": ("dark", "dark_heading", "dark_fgm", "all lamps off: heading fixes"),
    "dark_pose": ("dark", "dark_pose", "dark_fgm", "all lamps off: pose fixes"),
    "people_pose": ("people", "people_pose", "people_fgm", "people and boxes: pose fixes"),
}

# Estimates an evaluation puts side by side (evaluate --compare): B against C on the
# paper log; every lamp off: pose fixes against heading fixes and against none (issue 8)
COMPARE: dict[str, tuple[str, ...]] = {
    "C": ("AB",),
    "dark_pose": ("dark_heading", "dark_none"),
}

# Estimates and evaluations of the paper's own phases (A-D); the others go beyond it.
PAPER_ONLY = ("AB", "C", "D")

# Expected seconds of each command on the full scenario: a step's CPU time in a
# ``reproduce --seeds 1`` on a 2-core machine (2026-12-02), with fixes from the FGM
# freeze (phase C: the aid at work over the last 2 of the 6 runs)
COST = {"simulate": 3.5, "run": 2.0, "run_heading": 4.3, "run_pose": 5.0, "map": 1.6}
COST_EVALUATE = 1.5
# A run with fixes from the log's start (``--fix-from``, phase D: the bumps from run 1)
# has its aid at work over all 6 runs instead of the last 2: the aid's share of the cost
# (run_heading - run) three times, 2.0 + 3 x 2.3 = 8.9 s (9.4 s measured). Without it D
# ranked with C and started last, its 9 s the tail of the plan.
FIX_FROM_START = 3.0


def compare_label(estimate: str) -> str:
    """The report's name of an estimate directory (the label of its own evaluation)."""
    return next(lab for _, est, _, lab in EVALUATIONS.values() if est == estimate)


def evaluations(beyond: bool = True) -> dict[str, tuple[str, str, str, str]]:
    """The evaluations of the plan: all, or the paper's phases only."""
    return {k: v for k, v in EVALUATIONS.items() if beyond or k in PAPER_ONLY}


def seed_steps(
    seed: int, suite: Suite, beyond: bool = True, calibrated: frozenset[str] = frozenset()
) -> list[Step]:
    """Every step of one seed, in a valid order (dependencies first); ``beyond=False``
    keeps only the paper's phases A-D (no dark or people logs, no pose fixes);
    ``calibrated``: the logs whose config calibrates the odometry (``slam.calibrate``):
    their maps name the run's calibration.csv (``map --calibration``)."""
    d = f"seed{seed}"
    logs = {"paper": suite.paper, "bumps": suite.bumps}
    if beyond:
        logs |= {"dark": suite.dark, "people": suite.people}
    steps: list[Step] = []

    def add(
        name: str, kind: str, argv: list[str], deps: list[str], cost: float, call: dict
    ) -> None:
        steps.append(
            Step(
                f"{d}/{name}",
                tuple(argv),
                tuple(f"{d}/{x}" for x in deps),
                cost,
                kind,
                tuple(call.items()),
            )
        )

    for name, config in logs.items():
        add(
            f"{name}.mcap",
            "simulate",
            ["simulate", config, "-o", f"{d}/{name}.mcap", "--seed", str(seed)],
            [],
            COST["simulate"],
            {"config": config, "output": f"{d}/{name}.mcap", "seed": seed},
        )

    def run(
        name: str, log: str, fix: str = "none", fgm: str = "", fix_from: float | None = None
    ) -> None:
        argv = ["run", f"{d}/{log}.mcap", "-o", f"{d}/{name}", "--config", logs[log]]
        call: dict[str, Any] = {"log": argv[1], "outdir": argv[3], "config": logs[log]}
        deps = [f"{log}.mcap"]
        if fix != "none":
            argv += ["--map", f"{d}/{fgm}", "--fix", fix]
            call |= {"map_dir": f"{d}/{fgm}", "fix": fix}
            if fix_from is not None:
                argv += ["--fix-from", f"{fix_from:g}"]
                call["fix_from"] = LogTime(fix_from)  # as the CLI parses the option
            deps.append(fgm)
        cost = COST["run"] if fix == "none" else COST[f"run_{fix}"]
        if fix_from is not None:  # the aid from the log's start (the plan gives only 0)
            cost = COST["run"] + FIX_FROM_START * (cost - COST["run"])
        add(name, "run", argv, deps, cost, call)

    def fgm(name: str, log: str, est: str) -> None:
        argv = [
            "map", f"{d}/{log}.mcap", "--trajectory", f"{d}/{est}/trajectory.tum",
            "--landmarks", f"{d}/{est}/landmarks.yaml", "-o", f"{d}/{name}",
            "--config", logs[log],
        ]  # fmt: skip
        call = {"log": argv[1], "trajectory": argv[3], "outdir": argv[7], "config": logs[log]}
        call["landmarks"] = argv[5]
        if log in calibrated:  # named, so that --ship-files sends it with the task
            call["calibration"] = f"{d}/{est}/calibration.csv"
            argv += ["--calibration", call["calibration"]]
        add(name, "map", argv, [f"{log}.mcap", est], COST["map"], call)

    run("AB", "paper")
    fgm("fgm", "paper", "AB")
    run("C", "paper", "heading", "fgm")
    run("D", "bumps", "heading", "fgm", fix_from=0.0)
    if beyond:
        run("C_pose", "paper", "pose", "fgm")
        for log in ("dark", "people"):
            run(f"{log}_none", log)
            fgm(f"{log}_fgm", log, f"{log}_none")
        run("dark_heading", "dark", "heading", "dark_fgm")
        run("dark_pose", "dark", "pose", "dark_fgm")
        run("people_pose", "people", "pose", "people_fgm")

    for name, (log, est, map_dir, label) in evaluations(beyond).items():
        argv = [
            "evaluate", f"{d}/{log}.mcap", f"{d}/{est}", "-o", f"{d}/eval_{name}",
            "--map", f"{d}/{map_dir}", "--label", label,
        ]  # fmt: skip
        others = COMPARE.get(name, ())
        for other in others:
            argv += ["--compare", f"{compare_label(other)}={d}/{other}"]
        deps = [f"{log}.mcap", est, map_dir, *others]
        call = {"truth": argv[1], "estimate": argv[2], "outdir": argv[4], "map_dir": argv[6]}
        call |= {"label": label, "compare": tuple(f"{compare_label(o)}={d}/{o}" for o in others)}
        add(f"eval_{name}", "evaluate", argv, deps, COST_EVALUATE, call)
    return steps


def build_plan(
    seeds: list[int], suite: Suite, beyond: bool = True, calibrated: frozenset[str] = frozenset()
) -> list[Step]:
    """The steps of every seed (:func:`seed_steps`); keys are unique and every dependency
    is a step."""
    steps = [s for seed in seeds for s in seed_steps(seed, suite, beyond, calibrated)]
    keys = {s.key for s in steps}
    if len(keys) != len(steps):
        raise ValueError("duplicate step keys in the plan")
    for s in steps:
        missing = [k for k in s.deps if k not in keys]
        if missing:
            raise ValueError(f"step {s.key} depends on unknown steps {missing}")
    return steps


def critical_path(steps: list[Step]) -> dict[str, float]:
    """Longest expected cost from each step to the end of the graph (itself included).

    Run first the step with the longest remaining chain (list scheduling by critical path,
    Hu 1961), so that the last seconds are not spent waiting on one long chain.
    """
    children: dict[str, list[str]] = {s.key: [] for s in steps}
    for s in steps:
        for d in s.deps:
            children[d].append(s.key)
    cost = {s.key: s.cost for s in steps}
    memo: dict[str, float] = {}
    for s in reversed(_topological(steps)):
        memo[s.key] = cost[s.key] + max((memo[c] for c in children[s.key]), default=0.0)
    return memo


def ready_order(ready: list[Step], prio: dict[str, float]) -> list[Step]:
    """The steps whose dependencies are done, in the order they start: longest remaining
    chain first (:func:`critical_path`), ties by key (the same order on every run).

    Parameters
    ----------
    ready : list of Step
        Steps that may start.
    prio : dict
        :func:`critical_path` of the plan.

    Returns
    -------
    list of Step
    """
    return sorted(ready, key=lambda s: (-prio[s.key], s.key))


def _topological(steps: list[Step]) -> list[Step]:
    """Steps ordered so that each comes after its dependencies (Kahn's algorithm)."""
    by_key = {s.key: s for s in steps}
    indeg = {s.key: len(s.deps) for s in steps}
    children: dict[str, list[str]] = {s.key: [] for s in steps}
    for s in steps:
        for d in s.deps:
            children[d].append(s.key)
    ready = [s.key for s in steps if indeg[s.key] == 0]
    order: list[Step] = []
    while ready:
        k = ready.pop(0)
        order.append(by_key[k])
        for c in children[k]:
            indeg[c] -= 1
            if indeg[c] == 0:
                ready.append(c)
    if len(order) != len(steps):
        raise ValueError("the plan has a dependency cycle")
    return order
