"""Steps whose files travel with the task, for Dask workers without a shared filesystem.

The client packs the files a step reads (every argument naming a file or directory of the
plan's directory, or an absolute path, and the plan directory's top-level ``*.yaml``: the
configs a sweep's grid points extend) into the task as bytes. The worker writes them into
a private temporary directory, runs the step there (``execute.run_step``) and sends back
the bytes of what the step wrote (its ``-o`` output, a file or a directory, and
``--truth-tum`` / ``--preview``). The client writes those into the plan's directory:
a directory output into a temporary directory beside it first, renamed into place whole
(outputs complete or absent). Arguments that are absolute paths are shipped as
``_in/J/NAME`` and the step's command is rewritten to name them there.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from fuzzyslam.rundir import split_label

OUTPUT_OPTIONS = ("-o", "--output", "--truth-tum", "--preview")


def outputs_of(argv: tuple[str, ...]) -> list[str]:
    """The paths a step writes: the values of its output options."""
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a in OUTPUT_OPTIONS]


def _files(path: Path) -> list[Path]:
    return [path] if path.is_file() else sorted(f for f in path.rglob("*") if f.is_file())


def rewrite_call(call: tuple, argv: tuple[str, ...], shipped: tuple[str, ...]) -> tuple:
    """A step's stage call with every path the shipped command renamed (``argv`` ->
    ``shipped``, from :func:`pack_inputs`) renamed alike, also inside tuples and
    ``LABEL=PATH`` values."""
    names = {a: b for a, b in zip(argv, shipped, strict=True) if a != b}

    def one(v):
        if isinstance(v, str):
            if v in names:
                return names[v]
            label, path = split_label(v)
            return f"{label}={names[path]}" if label is not None and path in names else v
        if isinstance(v, tuple):
            return tuple(one(x) for x in v)
        return v

    return tuple((k, one(v)) for k, v in call)


def pack_inputs(argv: tuple[str, ...], root: Path) -> tuple[tuple[str, ...], dict[str, bytes]]:
    """(the command as the worker runs it, {relative path: bytes}) of the files a step
    reads (module docstring)."""
    outs = set(outputs_of(argv))
    files: dict[str, bytes] = {f.name: f.read_bytes() for f in sorted(root.glob("*.yaml"))}
    new = list(argv)
    for j, arg in enumerate(argv):
        if arg in outs or arg.startswith("-"):
            continue
        a, prefix = arg, ""
        p = Path(a) if os.path.isabs(a) else root / a
        if not p.exists():  # LABEL=PATH (evaluate --compare)
            label, a = split_label(arg)
            prefix = "" if label is None else f"{label}="
            p = Path(a) if os.path.isabs(a) else root / a
        if not p.exists():
            continue
        rel = Path(a) if not os.path.isabs(a) else Path("_in", str(j), p.name)
        new[j] = prefix + str(rel)
        for f in _files(p):
            files[str(rel / f.relative_to(p)) if p.is_dir() else str(rel)] = f.read_bytes()
    return tuple(new), files


def run_shipped_step(
    kind: str, call: tuple, argv: tuple[str, ...], files: dict[str, bytes]
) -> tuple:
    """Run a step (stage ``kind``, its ``call``; ``argv`` its shipped command, which names
    its outputs) in a private temporary directory holding ``files``; the result of
    ``execute.run_step`` with, last, {relative path: bytes} of its outputs (each output
    a file, or a directory: its files under it)."""
    from fuzzyslam.reproduce.execute import run_step

    with tempfile.TemporaryDirectory(prefix="fuzzyslam-step.") as tmp:
        d = Path(tmp)
        for rel, data in files.items():
            (d / rel).parent.mkdir(parents=True, exist_ok=True)
            (d / rel).write_bytes(data)
        for o in outputs_of(argv):
            (d / o).parent.mkdir(parents=True, exist_ok=True)
        res = run_step(kind, call, str(d))
        produced: dict[str, bytes] = {}
        if res[0]:
            for o in outputs_of(argv):
                if (d / o).exists():
                    produced |= {str(f.relative_to(d)): f.read_bytes() for f in _files(d / o)}
    return (*res, produced)


def write_outputs(argv: tuple[str, ...], produced: dict[str, bytes], root: Path) -> None:
    """Write a shipped step's outputs into ``root``: each output file atomically, each
    output directory built beside its place and renamed onto it whole."""
    from fuzzyslam.fileio import atomic_path

    for o in outputs_of(argv):
        mine = {k: v for k, v in produced.items() if k == o or k.startswith(o.rstrip("/") + "/")}
        dest = root / o
        dest.parent.mkdir(parents=True, exist_ok=True)
        if set(mine) == {o}:
            with atomic_path(dest) as tmp:
                tmp.write_bytes(mine[o])
            continue
        if not mine:
            continue
        build = Path(tempfile.mkdtemp(prefix=f".{dest.name}.", suffix=".part", dir=dest.parent))
        try:
            for rel, data in mine.items():
                f = build / Path(rel).relative_to(o)
                f.parent.mkdir(parents=True, exist_ok=True)
                f.write_bytes(data)
            if dest.is_dir():
                shutil.rmtree(dest)
            os.replace(build, dest)
        except BaseException:
            shutil.rmtree(build, ignore_errors=True)
            raise
