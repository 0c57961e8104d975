"""Benchmark of reading MCAP logs: fuzzyslam's reader against mcap + rosbags.

    python benchmarks/bench_read.py [--real DIR] [--base REV] [--no-run]

For (a) a simulated paper log (made in a temporary directory with `fuzzyslam simulate
paper`) and (b) the real logs under DIR (default ../shared/data/real relative to the
repository: mrclam6-robot2, carmen-fr079; skipped when absent), prints per message type:

- read: messages/s of ``LogReader.messages(topics of that type)`` (index, decompress,
  decode) against the mcap library's ``iter_messages`` + rosbags' ``deserialize_cdr``
  on the same topics (best of 3, the two interleaved);
- decode: microseconds a message of ``streams/cdr.py``'s decoder against rosbags'
  deserializer on the same payloads (``time_decode``), and the ratio.

Then (c) ``fuzzyslam run`` on the paper log, wall time of this tree against revision REV
(default: the merge base with main, extracted with ``git archive``), interleaved 3 times
each, with the same Python and dependencies.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("FUZZYSLAM_NO_PROGRESS", "1")

from mcap.reader import make_reader

from fuzzyslam.streams.cdr import DECODERS
from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.typestore import deserialize

ROOT = Path(__file__).resolve().parents[1]
REAL = ("mrclam6-robot2", "carmen-fr079")
SAMPLE_PER_TYPE = 3000  # payloads per type for the decode timing


def topics_by_type(reader: LogReader) -> dict[str, list[str]]:
    out: dict[str, list[str]] = defaultdict(list)
    for topic, typename in sorted(reader.topics.items()):
        if reader.counts.get(topic, 0) > 10:
            out[typename].append(topic)
    return out


def read_new(log: Path, topics: list[str]) -> tuple[int, float]:
    t0 = time.perf_counter()
    n = sum(1 for _ in LogReader(log).messages(topics))
    return n, time.perf_counter() - t0


def read_mcap_rosbags(log: Path, topics: list[str]) -> tuple[int, float]:
    t0 = time.perf_counter()
    n = 0
    with open(log, "rb") as f:
        for schema, _ch, m in make_reader(f).iter_messages(topics=topics, log_time_order=True):
            deserialize(m.data, schema.name)
            n += 1
    return n, time.perf_counter() - t0


def payloads(log: Path, topics: list[str]) -> list[bytes]:
    out = []
    with open(log, "rb") as f:
        for _s, _c, m in make_reader(f).iter_messages(topics=topics):
            out.append(bytes(m.data))
            if len(out) >= SAMPLE_PER_TYPE:
                break
    return out


def time_decode(fast, slow, data: list[bytes], block: int = 100, rounds: int = 7):
    """Microseconds a message of ``fast`` and ``slow`` on ``data``: blocks of ``block``
    payloads timed alternately, the minimum of ``rounds`` kept per block (the machine is
    shared: a load spike hits one block of one round, not the figure)."""
    blocks = [data[k : k + block] for k in range(0, len(data), block)]
    best = {fast: [float("inf")] * len(blocks), slow: [float("inf")] * len(blocks)}
    for _ in range(rounds):
        for i, b in enumerate(blocks):
            for fn in (fast, slow):
                t0 = time.perf_counter()
                for x in b:
                    fn(x)
                best[fn][i] = min(best[fn][i], time.perf_counter() - t0)
    return tuple(sum(best[fn]) / len(data) * 1e6 for fn in (fast, slow))


def bench_log(name: str, log: Path) -> None:
    reader = LogReader(log)
    print(
        f"\n== {name}: {log} ({log.stat().st_size / 1e6:.1f} MB, {reader.end - reader.start:.0f} s)"
    )
    print(
        f"{'type':34s} {'msgs':>7s} {'new msg/s':>10s} {'mcap+rosbags':>12s} {'x':>5s}"
        f" | {'decode us':>9s} {'rosbags us':>10s} {'x':>5s}"
    )
    for typename, topics in topics_by_type(reader).items():
        best_new = best_old = float("inf")
        n = 0
        for _ in range(3):
            n, dt = read_new(log, topics)
            best_new = min(best_new, dt)
            n_old, dt = read_mcap_rosbags(log, topics)
            best_old = min(best_old, dt)
            assert n == n_old, (typename, n, n_old)
        line = (
            f"{typename:34s} {n:7d} {n / best_new:10.0f} {n / best_old:12.0f} "
            f"{best_old / best_new:5.1f}"
        )
        fast = DECODERS.get(typename)
        if fast is not None:
            data = payloads(log, topics)
            a, b = time_decode(fast, lambda x, t=typename: deserialize(x, t), data)
            line += f" | {a:9.2f} {b:10.2f} {b / a:5.1f}"
        print(line, flush=True)


def bench_run(log: Path, base_rev: str) -> None:
    """``fuzzyslam run`` of this tree and of ``base_rev``, interleaved 3 times each."""
    with tempfile.TemporaryDirectory() as d:
        base = Path(d) / "base"
        base.mkdir()
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", base_rev], check=True, capture_output=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
        trees = {"base": base, "this": ROOT}
        times: dict[str, list[float]] = {k: [] for k in trees}
        outs = {}
        for _ in range(3):
            for k, tree in trees.items():
                out = Path(d) / f"out_{k}"
                shutil.rmtree(out, ignore_errors=True)
                env = {**os.environ, "PYTHONPATH": str(tree)}
                t0 = time.perf_counter()
                subprocess.run(
                    [sys.executable, "-m", "fuzzyslam", "run", str(log), "-o", str(out)],
                    check=True, cwd=d, env=env, stdout=subprocess.DEVNULL,
                )  # fmt: skip
                times[k].append(time.perf_counter() - t0)
                outs[k] = {
                    p.name: p.read_bytes() for p in out.iterdir() if p.name != "summary.json"
                }
        same = outs["base"] == outs["this"]
        print(f"\n== fuzzyslam run on {log.name}: this tree vs {base_rev[:10]} (wall s, 3 each)")
        for k, ts in times.items():
            print(f"{k:5s} " + " ".join(f"{t:6.2f}" for t in ts) + f"  min {min(ts):.2f}")
        print(
            f"ratio this/base (min): {min(times['this']) / min(times['base']):.3f}; "
            f"outputs but summary.json identical: {same}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    real = [p / "shared" / "data" / "real" for p in (ROOT.parent, ROOT.parent.parent)]
    ap.add_argument("--real", type=Path, default=next((p for p in real if p.is_dir()), real[0]))
    ap.add_argument("--base", default=None, help="revision to compare `run` against")
    ap.add_argument("--no-run", action="store_true", help="skip the `run` comparison")
    ap.add_argument("--log", type=Path, default=None, help="paper log (else simulated)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        log = args.log
        if log is None:
            log = Path(d) / "paper.mcap"
            print("simulating the paper log ...", flush=True)
            subprocess.run(
                [sys.executable, "-m", "fuzzyslam", "simulate", "paper", "-o", str(log)],
                check=True, stdout=subprocess.DEVNULL,
            )  # fmt: skip
        bench_log("simulated paper log", log)
        for name in REAL:
            real = args.real / name / "log.mcap"
            if real.exists():
                bench_log(name, real)
            else:
                print(f"\n== {name}: {real} absent, skipped")
        if not args.no_run:
            rev = args.base or subprocess.run(
                ["git", "-C", str(ROOT), "merge-base", "HEAD", "main"],
                check=True, capture_output=True, text=True,
            ).stdout.strip()  # fmt: skip
            bench_run(log, rev)


if __name__ == "__main__":
    main()
