"""Would a producer thread for the input work make ``run`` faster on 2 cores? (issue 16)

(The experiment before ``run`` had its input process: the ``--process`` variant is now
``fuzzyslam/slam/prefetch.py``, with the child's state sent back; ``run``'s own
``--prefetch``/``--no-prefetch`` are compared by ``bench_run.py --prefetch``.)

    python benchmarks/bench_prefetch.py [LOG.mcap] [--pairs 8] [--batch 64]
        [--chunks | --process] [--map FGMDIR --fix heading|pose]

The experiment behind "no input thread" (README, Performance): the events of
``LogInputs.events`` (chunk decompression, CDR decoding, lamp detection: pure per
message, in order) are made by a producer thread and handed to the filter on the main
thread in batches of ``--batch`` through a bounded queue (8 batches); ``--chunks``
threads only the chunk reads and decompression (``indexed_messages``) instead;
``--process`` makes the events in a forked child process instead of a thread, sent as
pickled batches through a pipe (whose buffer bounds the memory; no GIL shared). A
measurement only: the child's glitch counts (``warnings``, the reader's damage) are not
sent back, so summary.json differs there. With ``--map`` and ``--fix`` the runs have the
aids (built anew for each run) and the events include the sonar rings. In one warm
process the run stage (``slam.stage.run_stage``, paper config) alternates unthreaded
and threaded, ``--pairs`` times (the order swapped every pair), and prints the wall and
CPU time (children included) of each and the outputs' identity; then, for one threaded
run, each thread's CPU time (``time.thread_time``): what the two threads would take on
two free cores without the GIL.

Where the measurement is taken matters: on a machine whose cores are busy with other
jobs the second thread finds no core, and the comparison says nothing about 2 cores.
This experiment's figures (README) come from a new session whose scheduling group
(``/proc/self/autogroup``) was given nice -15, so that the other helpers' jobs left it
nearly two cores; run the script as
``setsid sh -c 'echo -15 > /proc/self/autogroup; exec python benchmarks/bench_prefetch.py'``
(root), or on an idle machine.
"""

from __future__ import annotations

import argparse
import filecmp
import multiprocessing
import os
import pickle
import queue
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

os.environ.setdefault("FUZZYSLAM_NO_PROGRESS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from fuzzyslam.config import load_config
from fuzzyslam.slam import inputs
from fuzzyslam.slam.stage import run_stage
from fuzzyslam.streams import reader

_END = object()
STATS: dict[str, float] = {}


def prefetched(items: Iterable, batch: int, depth: int = 8) -> Iterator:
    """``items`` made by a producer thread, in order, through a queue of ``depth`` batches
    of ``batch``; an exception of the producer raised here."""
    q: queue.Queue = queue.Queue(depth)

    def produce() -> None:
        t0 = time.thread_time()
        try:
            buf = []
            for item in items:
                buf.append(item)
                if len(buf) >= batch:
                    q.put(buf)
                    buf = []
            q.put(buf)
            q.put(_END)
        except BaseException as exc:
            q.put(exc)
        STATS["producer_cpu"] = STATS.get("producer_cpu", 0.0) + time.thread_time() - t0

    threading.Thread(target=produce, daemon=True).start()
    while (got := q.get()) is not _END:
        if isinstance(got, BaseException):
            raise got
        yield from got


def _child(conn, events: Iterable, batch: int) -> None:
    """The events of a forked child to the parent, pickled in batches; then b"" (or
    an exception, pickled after a b"!")."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    try:
        buf = []
        for ev in events:
            buf.append(ev)
            if len(buf) >= batch:
                conn.send_bytes(pickle.dumps(buf, 5))
                buf = []
        conn.send_bytes(pickle.dumps(buf, 5))
        conn.send_bytes(b"")
    except BaseException as exc:
        conn.send_bytes(b"!" + pickle.dumps(exc))
    conn.close()


def from_process(events: Iterable, batch: int) -> Iterator:
    """``events`` made by a forked child process, in order (pickled batches, a pipe)."""
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, events, batch), daemon=True)
    proc.start()
    send.close()
    try:
        while data := recv.recv_bytes():
            if data[:1] == b"!":
                raise pickle.loads(data[1:])
            yield from pickle.loads(data)
    finally:
        proc.terminate()
        proc.join()


def cpu_with_children() -> float:
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", nargs="?", type=Path, default=None)
    ap.add_argument("--pairs", type=int, default=8)
    ap.add_argument("--batch", type=int, default=64)
    ap.add_argument("--chunks", action="store_true", help="thread the chunk reads only")
    ap.add_argument("--process", action="store_true", help="a child process, not a thread")
    ap.add_argument("--map", type=Path, default=None, help="FGMDIR (run --map)")
    ap.add_argument("--fix", default=None, help="heading|pose (run --fix)")
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench_prefetch."))
    log = args.log
    if log is None:
        log = work / "paper.mcap"
        subprocess.run(["fuzzyslam", "simulate", "paper", "-o", str(log), "--seed", "0"],
                       check=True, stdout=subprocess.DEVNULL)  # fmt: skip
    threaded = {"on": False}
    events, indexed = inputs.LogInputs.events, reader.indexed_messages

    def events_maybe_threaded(self, rings=False, ring_start=None):
        ev = events(self, rings, ring_start)
        if not threaded["on"] or args.chunks:
            return ev
        return from_process(ev, args.batch) if args.process else prefetched(ev, args.batch)

    def chunks_maybe_threaded(*a, **k):
        batches = indexed(*a, **k)
        return prefetched(batches, 1, 4) if threaded["on"] and args.chunks else batches

    inputs.LogInputs.events = events_maybe_threaded
    reader.indexed_messages = chunks_maybe_threaded
    cfg = load_config("paper")

    def run(out: Path) -> None:
        aids = []
        if args.map is not None:
            from fuzzyslam.fixes.aids import aids_for_log

            aids = aids_for_log(args.map, args.fix, cfg, log)
        run_stage(log, out, cfg, aids)

    run(work / "warm")  # imports, caches
    times: dict[str, list[tuple[float, float]]] = {"off": [], "on": []}
    for i in range(args.pairs):
        for mode in ("off", "on") if i % 2 == 0 else ("on", "off"):
            threaded["on"] = mode == "on"
            c0, w0 = cpu_with_children(), time.perf_counter()
            run(work / mode)
            times[mode].append((time.perf_counter() - w0, cpu_with_children() - c0))
    same = all(
        filecmp.cmp(f, work / "on" / f.name, shallow=False)
        for f in (work / "off").iterdir()
        if f.name != "summary.json"  # its wall time differs
    )
    threaded["on"] = True
    STATS.clear()
    m0 = time.thread_time()
    run(work / "on")
    main_cpu = time.thread_time() - m0
    dur = inputs.open_inputs(log, cfg)
    dur = dur.end - dur.start
    how = "in a child process" if args.process else "threaded"
    print(f"log {log}: {dur:.1f} s; fix {args.fix}; {'chunk reads' if args.chunks else 'events'} "
          f"{how}, batches of {args.batch}; {args.pairs} pairs; load average "
          f"{os.getloadavg()[0]:.2f}")  # fmt: skip
    for mode, rows in times.items():
        wall = sorted(w for w, _ in rows)
        cpu = sorted(c for _, c in rows)
        w, c = wall[len(wall) // 2], cpu[len(cpu) // 2]
        print(f"{how if mode == 'on' else 'one thread':>18}: wall median {w:.3f} s "
              f"(best {wall[0]:.3f}), CPU median {c:.3f} s (best {cpu[0]:.3f}); real time "
              f"{dur / w:.0f}x wall, {dur / c:.0f}x CPU")  # fmt: skip
    print(f"outputs byte-identical (summary.json aside): {same}")
    print(f"one run {how}, CPU of the main thread {main_cpu:.3f} s, of the producer "
          f"thread(s) {STATS.get('producer_cpu', float('nan')):.3f} s")  # fmt: skip


if __name__ == "__main__":
    main()
