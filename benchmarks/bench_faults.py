"""Fault-injection benchmark (issue 14): random variants of each failure class, counted.

    python benchmarks/bench_faults.py [--variants 4] [--seed 0] [--classes 1,2,3,4,5,6,7]
                                      [--workdir DIR] [--keep]

Each trial runs one ``fuzzyslam`` command in a child process (30 s timeout) on a short
simulated log, with a fault injected for real, and checks what the CLI promises:

1. disk full: ``simulate`` onto an existing log and ``run`` into an existing directory
   under a random file-size limit (RLIMIT_FSIZE), and ``simulate`` onto a small tmpfs
   of random size when mounting is allowed (root); Ctrl-C at a random moment of
   ``simulate`` onto an existing log. Expected: exit 3 ("no space left", the user's
   path, no ``.part``) or 130, and the old output byte-identical (or, after Ctrl-C
   that came too late to matter, the complete new one).
2. special files: a FIFO or a socket as the output of a random command, or inside a
   run directory. Expected: exit 3 and the node unchanged.
4. silent wrong results: one JointState jump of random size and sign, an impossible
   CameraInfo, sonar max ranges of 1e3..1e30 m. Expected: exit 0 with the glitch
   counted and the final pose within 1 cm of the clean run's, or exit 3 (CameraInfo).
5. configs: alias bombs, huge or non-finite numbers in random fields, long lists,
   deep nesting, long ``extends`` chains, ``extends`` outside the config's folder.
   Expected: exit 3, one line, in under a second.
6. damaged maps: fgm.npz with a random bad resolution, origin, shape or freeze time.
   Expected: exit 3 from ``run --map``.
7. exit codes: an unreadable log (as an unprivileged user, root only), junk logs of
   random bytes. Expected: exit 3, one line naming the file.

3. corrupt structure: a random bit flipped in a chunk's header fields, a chunk index's
   chunk offset moved by +-64 KiB, a message index whose length is not a multiple of 16.
   Expected: ``run`` exits 0 or 3, never 1; with exit 0, a result that differs from the
   clean run's must come with ``log_damage`` saying so.

Prints, per class, the counts: tried, wrong exit code, output lost or mixed, hang > 30 s,
silent wrong result; exits 1 if any is not 0.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import resource
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fuzzyslam.streams.reader import LogReader
from fuzzyslam.streams.writer import LogWriter

TIMEOUT = 30.0
# the short scenario of tests/test_faults.py (1/10 of a lap)
MICRO_YAML = (Path(__file__).parents[1] / "tests" / "micro.yaml").read_text(encoding="utf-8")
ENV = {**os.environ, "FUZZYSLAM_NO_PROGRESS": "1", "MPLBACKEND": "Agg"}
JOINTS, INFO, SONAR = "/joint_states", "/ceiling_camera/camera_info", "/sonar/s"


@dataclass
class Counts:
    tried: int = 0
    wrong_exit: int = 0
    lost_or_mixed: int = 0
    hang: int = 0
    silent_wrong: int = 0
    notes: list[str] = field(default_factory=list)

    def failures(self) -> int:
        return self.wrong_exit + self.lost_or_mixed + self.hang + self.silent_wrong


@dataclass
class Result:
    code: int | None  # None: killed after TIMEOUT
    stdout: str
    stderr: str
    seconds: float


def fuzzyslam(args: list[object], cwd: Path, fsize: int | None = None, user: bool = False,
              interrupt_after: float | None = None) -> Result:
    """Run ``fuzzyslam ARGS`` in a child (file-size limit, unprivileged user, SIGINT)."""
    cmd = [sys.executable, "-m", "fuzzyslam", *map(str, args)]
    if user:
        cmd = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", *cmd]

    def limit() -> None:
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, cwd=cwd, env={**ENV, "MPLCONFIGDIR": str(cwd)},
                         preexec_fn=limit, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    try:
        if interrupt_after is not None:
            try:
                out, err = p.communicate(timeout=interrupt_after)
                return Result(p.returncode, out, err, time.perf_counter() - t0)
            except subprocess.TimeoutExpired:
                p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=TIMEOUT)
        return Result(p.returncode, out, err, time.perf_counter() - t0)
    except subprocess.TimeoutExpired:
        p.kill()
        out, err = p.communicate()
        return Result(None, out, err, time.perf_counter() - t0)


def one_line(err: str, named: object, *words: str) -> bool:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    return (len(lines) == 1 and lines[0].startswith(f"fuzzyslam: error: {named}")
            and ".part" not in lines[0] and all(w in lines[0] for w in words))


def leftovers(folder: Path) -> list[Path]:
    return sorted(folder.glob(".*.part")) + sorted(folder.glob(".*.old"))


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def rewrite(src: Path, dst: Path, fault: Callable[[object], None]) -> Path:
    """Copy a log (metadata first), letting ``fault(message)`` change messages in place."""
    reader = LogReader(src)
    with LogWriter(dst) as w:
        for name in sorted(reader.metadata, key=lambda n: (n != "fuzzyslam.world", n)):
            w.metadata(name, reader.metadata[name])
        for m in reader.messages():
            fault(m)
            w.write(m.topic, m.typename, m.msg, m.t)
    return dst


class Bench:
    def __init__(self, work: Path, rng: random.Random) -> None:
        self.work, self.rng = work, rng
        self.cfg = work / "micro.yaml"
        self.cfg.write_text(MICRO_YAML, encoding="utf-8")
        self.log = work / "micro.mcap"
        self.est = work / "est"
        self.fgm = work / "fgm"
        self.check_ok(["simulate", self.cfg, "-o", self.log])
        self.run_summary = json.loads(
            self.check_ok(["run", self.log, "-o", self.est, "--config", self.cfg]).stdout
        )
        self.check_ok(["map", self.log, "--trajectory", self.est / "trajectory.tum", "--config",
                       self.cfg, "-o", self.fgm, "--no-figures", "--until", "10"])
        self.fresh = work / "fresh.mcap"  # what simulate --seed 3 writes, for Ctrl-C trials
        self.check_ok(["simulate", self.cfg, "-o", self.fresh, "--seed", "3"])

    def check_ok(self, args: list[object]) -> Result:
        r = fuzzyslam(args, self.work)
        if r.code != 0:
            raise SystemExit(f"setup failed: fuzzyslam {' '.join(map(str, args))}: {r.stderr}")
        return r

    def trial_dir(self) -> Path:
        return Path(tempfile.mkdtemp(prefix="t", dir=self.work))

    # -- class 1: disk full, Ctrl-C --------------------------------------------------------

    def class1(self, c: Counts) -> None:
        d = self.trial_dir()
        kind = self.rng.choice(["simulate", "run", "tmpfs", "ctrl-c"])
        if kind == "simulate":
            out = d / "old.mcap"
            shutil.copyfile(self.log, out)
            before = out.read_bytes()
            r = fuzzyslam(["simulate", self.cfg, "-o", out, "--seed", "3"], d,
                          fsize=self.rng.randrange(0, len(before)))
            self.judge(c, r, 3, one_line(r.stderr, out, "no space left"),
                       out.read_bytes() == before and not leftovers(d), kind)
        elif kind == "run":
            out = d / "est"
            shutil.copytree(self.est, out)
            (out / "trajectory.tum").write_text("0 0 0 0 0 0 0 1\n", encoding="utf-8")
            before = snapshot(out)
            biggest = max(len(b) for b in before.values())
            r = fuzzyslam(["run", self.log, "-o", out, "--config", self.cfg], d,
                          fsize=self.rng.randrange(0, biggest))
            self.judge(c, r, 3, one_line(r.stderr, out, "no space left"),
                       snapshot(out) == before and not leftovers(d), kind)
        elif kind == "tmpfs":
            size = self.rng.randrange(64, 1500) * 1024
            mnt = d / "fs"
            mnt.mkdir()
            if subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)],
                              capture_output=True).returncode != 0:
                c.notes.append("tmpfs: cannot mount (not root); skipped")
                return
            try:
                out = mnt / "old.mcap"
                old = self.log.read_bytes()[: size // 3]
                out.write_bytes(old)
                r = fuzzyslam(["simulate", self.cfg, "-o", out, "--seed", "3"], d)
                if r.code == 0:  # it fitted: the new log must be complete
                    self.judge(c, r, 0, True, out.read_bytes() == self.fresh.read_bytes(), kind)
                else:
                    self.judge(c, r, 3, one_line(r.stderr, out, "no space left"),
                               out.read_bytes() == old and not leftovers(mnt), kind)
            finally:
                subprocess.run(["umount", str(mnt)], check=True)
        else:
            out = d / "old.mcap"
            shutil.copyfile(self.log, out)
            before = out.read_bytes()
            r = fuzzyslam(["simulate", self.cfg, "-o", out, "--seed", "3"], d,
                          interrupt_after=self.rng.uniform(2.0, 5.0))
            after = out.read_bytes()
            whole = after == before or (r.code == 0 and after == self.fresh.read_bytes())
            self.judge(c, r, 130 if r.code != 0 else 0, True, whole and not leftovers(d), kind)

    # -- class 2: special files -------------------------------------------------------------

    def class2(self, c: Counts) -> None:
        d = self.trial_dir()
        if self.rng.random() < 0.5:
            node = d / "fifo"
            os.mkfifo(node)
        else:
            node = Path(tempfile.mkdtemp(prefix="s", dir="/tmp")) / "sock"
            s = socket.socket(socket.AF_UNIX)
            s.bind(str(node))
            s.close()
        inside = d / "est"
        inside.mkdir()
        os.symlink(node, inside / self.rng.choice(["trajectory.tum", "summary.json"]))
        args, named = self.rng.choice([
            (["simulate", self.cfg, "-o", node], node),
            (["simulate", self.cfg, "-o", d / "x.mcap", "--preview", node], node),
            (["run", self.log, "--config", self.cfg, "-o", node], node),
            (["map", self.log, "--trajectory", self.est / "trajectory.tum", "-o", node], node),
            (["evaluate", self.log, self.est, "-o", node], node),
            (["run", self.log, "--config", self.cfg, "-o", inside], None),
        ])
        mode, ino = os.stat(node).st_mode, os.stat(node).st_ino
        r = fuzzyslam(args, d)
        st = os.stat(node)
        ok_msg = one_line(r.stderr, named if named else inside, "not a regular file")
        self.judge(c, r, 3, ok_msg, st.st_mode == mode and st.st_ino == ino, "special")
        if node.name == "sock":
            shutil.rmtree(node.parent)

    # -- class 3: corrupt MCAP structure ----------------------------------------------------

    def records(self) -> list[tuple[int, int, int]]:
        """(opcode, offset, content length) of the micro log's records, walked from the
        magic to the footer."""
        data = self.log.read_bytes()
        out, pos = [], 8
        while pos + 9 <= len(data) - 8:
            op, length = data[pos], struct.unpack_from("<Q", data, pos + 1)[0]
            out.append((op, pos, length))
            if op == 0x02:  # footer
                break
            pos += 9 + length
        return out

    def class3(self, c: Counts) -> None:
        d = self.trial_dir()
        data = bytearray(self.log.read_bytes())
        recs = self.records()
        kind = self.rng.choice(["chunk header", "chunk index offset", "message index length"])
        if kind == "chunk header":
            _, off, _ = self.rng.choice([r for r in recs if r[0] == 0x06])
            byte = off + 1 + self.rng.randrange(0, 8 + 8 + 8 + 8 + 4 + 4)  # length .. compression
            data[byte] ^= 1 << self.rng.randrange(8)
        elif kind == "chunk index offset":
            _, off, _ = self.rng.choice([r for r in recs if r[0] == 0x08])
            field_ = off + 9 + 16  # message_start_time, message_end_time, chunk_start_offset
            value = struct.unpack_from("<Q", data, field_)[0] + self.rng.choice([-1, 1]) * 65536
            struct.pack_into("<Q", data, field_, max(value, 0))
        else:
            _, off, _ = self.rng.choice([r for r in recs if r[0] == 0x07])
            field_ = off + 9 + 2  # channel_id, then the byte length of the entries
            value = struct.unpack_from("<I", data, field_)[0]
            struct.pack_into("<I", data, field_, value + self.rng.choice([1, 8, 15]))
        log = d / "corrupt.mcap"
        log.write_bytes(bytes(data))
        r = fuzzyslam(["run", log, "-o", d / "est", "--config", self.cfg], d)
        right = True
        if r.code == 0:
            s = json.loads(r.stdout)
            dmg = s.get("log_damage", {})
            damaged = any(dmg.get(k) for k in ("truncated", "lost_bytes", "damaged_records",
                                                "undecodable"))
            same = s["counts"] == self.run_summary["counts"]
            right = same or damaged
        ok_code = r.code in (0, 3)
        self.judge(c, r, r.code if ok_code else 3, ok_code, True, kind, right)

    # -- class 4: implausible sensor values ---------------------------------------------------

    def class4(self, c: Counts) -> None:
        d = self.trial_dir()
        kind = self.rng.choice(["spike", "camera", "sonar"])
        if kind == "spike":
            jump = self.rng.choice([-1, 1]) * 10.0 ** self.rng.uniform(1.5, 300)
            at = self.rng.randrange(5, 150)
            n = {"seen": 0}

            def spike(m) -> None:
                if m.topic == JOINTS:
                    n["seen"] += 1
                    if n["seen"] == at:
                        m.msg.position = m.msg.position + np.array([jump, 0.0])

            log = rewrite(self.log, d / "spike.mcap", spike)
            r = fuzzyslam(["run", log, "-o", d / "est", "--config", self.cfg], d)
            right = False
            if r.code == 0:
                s = json.loads(r.stdout)
                end, clean = np.array(s["final_pose"]), np.array(self.run_summary["final_pose"])
                right = (s["warnings"].get("implausible_odometry") == 1
                         and float(np.hypot(*(end[:2] - clean[:2]))) < 0.01)
            self.judge(c, r, 0, True, True, kind, right)
        elif kind == "camera":
            bad = self.rng.choice(["fx0", "fy2", "inf", "1e300", "nan_cx", "neg"])

            def camera(m) -> None:
                if m.topic == INFO:
                    k = np.array(m.msg.k, dtype=float)
                    k[[0, 4, 2]] = {"fx0": (0, k[4], k[2]), "fy2": (k[0], 2 * k[4], k[2]),
                                    "inf": (np.inf, np.inf, k[2]), "1e300": (1e300, 1e300, k[2]),
                                    "nan_cx": (k[0], k[4], np.nan),
                                    "neg": (-k[0], -k[4], k[2])}[bad]
                    m.msg.k = k

            log = rewrite(self.log, d / "cam.mcap", camera)
            r = fuzzyslam(["run", log, "-o", d / "est", "--config", self.cfg], d)
            self.judge(c, r, 3, one_line(r.stderr, log, INFO), not (d / "est").exists(), kind)
        else:
            every = self.rng.randrange(3, 20)
            value = 10.0 ** self.rng.uniform(3, 30)
            n = {"seen": 0, "hit": 0}

            def sonar(m) -> None:
                if m.topic.startswith(SONAR):
                    n["seen"] += 1
                    if n["seen"] % every == 0:
                        n["hit"] += 1
                        m.msg.max_range = value

            log = rewrite(self.log, d / "sonar.mcap", sonar)
            r = fuzzyslam(["map", log, "--trajectory", self.est / "trajectory.tum", "--config",
                           self.cfg, "-o", d / "fgm", "--no-figures"], d)
            stats = json.loads(r.stdout)["sonar_stats"] if r.code == 0 else {}
            right = stats.get("implausible") == n["hit"]
            self.judge(c, r, 0, True, True, kind, right)

    # -- class 5: configs -------------------------------------------------------------------

    def class5(self, c: Counts) -> None:
        d = self.trial_dir()
        rng = self.rng
        q = "extends: quick.yaml\n"
        kind = rng.choice(["bomb", "number", "list", "nesting", "chain", "outside", "camera"])
        if kind == "bomb":
            k = rng.randrange(6, 12)
            text = "a0: &a0 [x, x, x, x, x, x, x, x, x, x]\n" + "".join(
                f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]\n" for i in range(1, k)
            ) + q
        elif kind == "number":
            field_ = rng.choice(["scenario: {start_offset: %s}", "robot: {max_speed: %s}",
                                 "world: {centerline: [[0, 0], [%s, 0], [10, 7], [0, 7]]}",
                                 "slam: {alpha: [%s, 1e-4, 1e-3, 1e-4, 3e-6, 6e-5]}",
                                 "fgm: {resolution: %s}"])
            value = rng.choice([".inf", "-.inf", ".nan", f"1e{rng.randrange(10, 308)}",
                                "9" * rng.randrange(20, 5000), f"-1e{rng.randrange(10, 300)}"])
            text = q + field_ % value + "\n"
        elif kind == "list":
            n = rng.randrange(10_001, 120_000)
            text = q + "world:\n  lamps: [" + "[1, 1], " * n + "]\n"
        elif kind == "nesting":
            n = rng.randrange(33, 3000)
            o, cl = rng.choice([("[", "]"), ("{a: ", "}")])
            text = q + "x: " + o * n + ("1" if o != "[" else "") + cl * n + "\n"
        elif kind == "chain":
            n = rng.randrange(17, 1500)
            for i in range(1, n):
                (d / f"c{i}.yaml").write_text(f"extends: c{i + 1}.yaml\n", encoding="utf-8")
            (d / f"c{n}.yaml").write_text(q, encoding="utf-8")
            text = "extends: c1.yaml\n"
        elif kind == "outside":
            (d.parent / "outside.yaml").write_text(q, encoding="utf-8")
            text = rng.choice(["extends: ../outside.yaml\n", f"extends: {d.parent}/outside.yaml\n"])
        else:
            w = rng.randrange(1025, 4097)
            text = q + f"camera: {{width: {w}, height: {w}, supersample: {rng.randrange(5, 17)}}}\n"
        cfg = d / "bad.yaml"
        cfg.write_text(text, encoding="utf-8")
        r = fuzzyslam(["simulate", cfg, "-o", d / "x.mcap"], d)
        # the child's own start-up (~1 s of imports) is not the config's: time it alone
        t0 = time.perf_counter()
        from fuzzyslam.config import load_config
        from fuzzyslam.errors import ConfigError

        try:
            load_config(cfg)
            fast = False
        except ConfigError:
            fast = time.perf_counter() - t0 < 1.0
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        short = len(lines) == 1 and len(lines[0]) < 300 + len(str(cfg))
        self.judge(c, r, 3, one_line(r.stderr, cfg) and short and fast,
                   not (d / "x.mcap").exists(), kind)

    # -- class 6: damaged maps --------------------------------------------------------------

    def class6(self, c: Counts) -> None:
        d = self.trial_dir()
        rng = self.rng
        key, value = rng.choice([
            ("resolution", rng.choice([0.0, -rng.uniform(0.01, 10), float("nan"),
                                       10.0 ** -rng.uniform(4, 300), float("inf")])),
            ("origin", [rng.choice([float("nan"), float("inf"), 1e300]), 0.0]),
            ("shape", [rng.choice([10**9, -3, 0]), 10]),
            ("freeze_time", float("nan")),
        ])
        bad = d / "fgm"
        shutil.copytree(self.fgm, bad)
        with np.load(self.fgm / "fgm.npz", allow_pickle=False) as z:
            entries = {k: z[k] for k in z.files}
        entries[key] = np.asarray(value)
        with open(bad / "fgm.npz", "wb") as f:
            np.savez_compressed(f, **entries)
        fix = rng.choice(["pose", "heading"])
        r = fuzzyslam(["run", self.log, "--config", self.cfg, "--map", bad, "--fix", fix,
                       "-o", d / "o"], d)
        self.judge(c, r, 3, one_line(r.stderr, bad / "fgm.npz"), not (d / "o").exists(), key)

    # -- class 7: exit codes ----------------------------------------------------------------

    def class7(self, c: Counts) -> None:
        d = self.trial_dir()
        if self.rng.random() < 0.5 and os.geteuid() == 0:
            d.chmod(0o777)
            for p in d.parents:
                if p == Path("/tmp"):
                    break
                p.chmod(p.stat().st_mode | 0o005)
            bad = d / "secret.mcap"
            shutil.copyfile(self.log, bad)
            bad.chmod(0)
            cmd = self.rng.choice(["run", "map", "evaluate"])
            args = {"run": ["run", bad, "-o", d / "o"],
                    "map": ["map", bad, "--trajectory", self.est / "trajectory.tum", "-o", d / "o"],
                    "evaluate": ["evaluate", bad, self.est, "-o", d / "o"]}[cmd]
            r = fuzzyslam(args, d, user=True)
            self.judge(c, r, 3, one_line(r.stderr, bad, "not readable"), not (d / "o").exists(),
                       "unreadable")
        else:
            junk = d / "junk.mcap"
            head = self.log.read_bytes()[: self.rng.randrange(0, 64)]
            junk.write_bytes(head + self.rng.randbytes(self.rng.randrange(0, 4096)))
            r = fuzzyslam(["run", junk, "-o", d / "o", "--config", self.cfg], d)
            self.judge(c, r, 3, one_line(r.stderr, junk), not (d / "o").exists(), "junk")

    # -- judging ----------------------------------------------------------------------------

    def judge(self, c: Counts, r: Result, code: int, message_ok: bool, output_ok: bool,
              kind: str, result_ok: bool = True) -> None:
        c.tried += 1
        if r.code is None:
            c.hang += 1
            c.notes.append(f"{kind}: hang")
            return
        if r.code != code or not message_ok:
            c.wrong_exit += 1
            c.notes.append(f"{kind}: exit {r.code} (want {code}): {r.stderr.strip()[:160]}")
        if not output_ok:
            c.lost_or_mixed += 1
            c.notes.append(f"{kind}: output lost or mixed")
        if not result_ok:
            c.silent_wrong += 1
            c.notes.append(f"{kind}: silent wrong result: {r.stdout[:160]}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", type=int, default=4, help="random variants per class")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--classes", default="1,2,3,4,5,6,7")
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--keep", action="store_true", help="keep the work directory")
    a = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench_faults_", dir=a.workdir))
    rng = random.Random(a.seed)
    t0 = time.perf_counter()
    try:
        bench = Bench(work, rng)
        table: dict[str, Counts] = {}
        for cls in a.classes.split(","):
            counts = table.setdefault(f"class {cls}", Counts())
            for _ in range(a.variants):
                try:
                    getattr(bench, f"class{cls}")(counts)
                except Exception as exc:  # an output the checks could not even read
                    counts.tried += 1
                    counts.silent_wrong += 1
                    counts.notes.append(f"unreadable outcome: {type(exc).__name__}: {exc}")
    finally:
        if not a.keep:
            shutil.rmtree(work, ignore_errors=True)
    cols = ("tried", "wrong_exit", "lost_or_mixed", "hang", "silent_wrong")
    print(f"{'class':<10}" + "".join(f"{h:>15}" for h in cols))
    total = Counts()
    for name, cnt in table.items():
        print(f"{name:<10}" + "".join(f"{getattr(cnt, h):>15}" for h in cols))
        for h in cols:
            setattr(total, h, getattr(total, h) + getattr(cnt, h))
    print(f"{'total':<10}" + "".join(f"{getattr(total, h):>15}" for h in cols))
    for name, cnt in table.items():
        for n in cnt.notes:
            print(f"  {name}: {n}")
    print(f"seed {a.seed}, {a.variants} variants per class, {time.perf_counter() - t0:.0f} s")
    sys.exit(1 if total.failures() else 0)


if __name__ == "__main__":
    main()
