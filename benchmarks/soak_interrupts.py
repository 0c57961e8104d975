"""Interruption soak: commands stopped by SIGTERM or Ctrl-C at random moments, counted.

    python benchmarks/soak_interrupts.py [--command sweep|run] [--runs 40] [--seed 0]
        [--loops 1] [--workdir DIR]

Each trial starts ``fuzzyslam`` in its own process group and sends SIGTERM or SIGINT
to the whole group (as a terminal's Ctrl-C reaches every process of it) at a random
moment, then checks what the CLI promises: the command ends within 60 s (else: a
hang, the processes' states printed and the soak stopped), with exit 0 (it finished
first), 130 or 143; no traceback on stderr; no process of the group left; no temporary
``.part`` output. A signal in the interpreter's own start-up (its first ~0.2 s, before
any fuzzyslam code runs or the CLI's SIGTERM handler is set) ends Python as Python
ends: by the signal's default action (a shell reports 130 or 143 as well), or, for
Ctrl-C during its ``site`` import, its fatal error and exit 1; such a trial passes if
nothing was written, and is counted apart.

- ``sweep``: 2 values x 2 seeds of sample.yaml (12 steps on the local pool, the test
  suite's sweep), the signal at 0-12 s: before the pool, while steps run and wait,
  and while the table is written.
- ``run``: ``run --map --fix pose`` on the paper log (its input, figure and /tf child
  processes), the signal at 0.1-4 s. The paper log and its FGM are made first in the
  work directory (about a minute).

``--loops K`` runs K trials at once (load: the races of a busy machine). Prints a line
per trial and the outcome counts. (The sweep's hang, fixed in ``fuzzyslam/interrupts.py``,
came once in about 20 trials of two loops; two faults of the same path once in a few
hundred.)
"""

from __future__ import annotations

import argparse
import collections
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

SWEEP = ("sweep", "sample.yaml", "--set", "robot.wheel_noise=0.002,0.03", "--seeds", "2")


def fuzzyslam(*args: str) -> list[str]:
    return [sys.executable, "-m", "fuzzyslam", *args]


def prepare(command: str, work: Path) -> tuple[list[str], tuple[float, float]]:
    """The command line of a trial (OUT standing for its output) and its signal window."""
    if command == "sweep":
        return fuzzyslam(*SWEEP, "-o", "OUT"), (0.0, 12.0)
    log, fgm = work / "paper.mcap", work / "fgm"
    if not fgm.exists():
        quiet = {"check": True, "stdout": subprocess.DEVNULL}
        subprocess.run(fuzzyslam("simulate", "paper", "-o", str(log), "--seed", "0"), **quiet)
        subprocess.run(fuzzyslam("run", str(log), "-o", str(work / "ab"), "--config", "paper"),
                       **quiet)  # fmt: skip
        subprocess.run(fuzzyslam("map", str(log), "--trajectory", str(work / "ab/trajectory.tum"),
                                 "--landmarks", str(work / "ab/landmarks.yaml"), "-o", str(fgm),
                                 "--config", "paper"), **quiet)  # fmt: skip
    argv = fuzzyslam("run", str(log), "--map", str(fgm), "--fix", "pose", "-o", "OUT",
                     "--config", "paper")  # fmt: skip
    return argv, (0.1, 4.0)


def trial(argv: list[str], window: tuple[float, float], rng: random.Random, work: Path) -> str:
    """One trial: its outcome ("ok", or what went wrong) and a line about it."""
    d = Path(tempfile.mkdtemp(dir=work))
    env = {k: v for k, v in os.environ.items() if k != "FUZZYSLAM_NO_PROGRESS"}
    env["MPLBACKEND"] = "Agg"
    cmd = [str(d / "out") if a == "OUT" else a for a in argv]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         env=env, cwd=d, start_new_session=True)  # fmt: skip
    at = rng.uniform(*window)
    sig = rng.choice([signal.SIGTERM, signal.SIGINT])
    time.sleep(at)
    try:
        os.killpg(p.pid, sig)
    except ProcessLookupError:
        pass
    try:
        _, err = p.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        os.system(f"ps -o pid,stat,wchan:20,cmd -g {p.pid}")
        return f"hang (pid {p.pid}, {sig.name} at {at:.2f} s, {d})"
    time.sleep(0.2)
    left = subprocess.run(["pgrep", "-g", str(p.pid)], capture_output=True, text=True).stdout
    parts = [str(x) for x in d.rglob("*.part*")]
    what = f"{sig.name} at {at:.2f} s: exit {p.returncode}"
    # in the interpreter's own start-up, before any fuzzyslam code runs: killed by the
    # signal's default action (a shell reports 130 or 143 too), or Python's fatal error
    # of an interrupted ``site`` import (exit 1); nothing written either way
    starting = p.returncode in (-signal.SIGTERM, -signal.SIGINT) or (
        p.returncode == 1 and "Fatal Python error: init_import_site" in err
    )
    if starting and not any(d.iterdir()):
        subprocess.run(["rm", "-rf", str(d)], check=False)
        return "ok, interrupted while Python starts"
    if p.returncode not in (0, 130, 143):
        return f"exit {p.returncode} ({what}): {err.strip().splitlines()[-1:]}"
    if "Traceback" in err:
        (work / f"traceback_{p.pid}.txt").write_text(err)
        return f"traceback ({what}; stderr in traceback_{p.pid}.txt)"
    if left.split():
        return f"processes left ({what}): {left.split()}"
    if parts:
        return f"temporary outputs left ({what}): {parts}"
    subprocess.run(["rm", "-rf", str(d)], check=False)
    return "ok"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--command", choices=("sweep", "run"), default="sweep")
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--loops", type=int, default=1, help="trials at once")
    ap.add_argument("--workdir", type=Path, default=None)
    args = ap.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="soak_interrupts."))
    work.mkdir(parents=True, exist_ok=True)
    argv, window = prepare(args.command, work.resolve())
    rngs = [random.Random(args.seed * 1000 + k) for k in range(args.loops)]
    counts: collections.Counter[str] = collections.Counter()
    failed: list[str] = []

    def loop(k: int) -> None:
        for i in range(k, args.runs, args.loops):
            outcome = trial(argv, window, rngs[k], work.resolve())
            if not outcome.startswith("ok"):
                failed.append(outcome)
            counts[outcome.split(" (")[0]] += 1
            print(f"{i:4d} {outcome}", flush=True)
            if outcome.startswith("hang"):
                return

    with ThreadPoolExecutor(args.loops) as pool:
        list(pool.map(loop, range(args.loops)))
    print(f"{args.command}: {sum(counts.values())} trials: " +
          ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))  # fmt: skip
    for line in failed:
        print("failed:", line)
    print(f"work directory: {work}")


if __name__ == "__main__":
    main()
