"""Safe output writing: temporary names renamed into place only when complete.

Every command writes through these helpers, so an error or Ctrl-C leaves no
partial file behind and an input is never overwritten.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

from fuzzyslam.errors import InputError

# Inputs of the current command: every file checked by ``check_input_file`` or named as
# an input of ``check_outputs`` while guarding is on (the CLI turns it on for each
# command). ``atomic_path`` and ``OutputDir`` refuse to replace any of them, so an
# input is never overwritten even when an output directory holds it.
_inputs: set[Path] = set()
_guarding = False


def guard_inputs(on: bool = True) -> None:
    """Start (and clear) or stop the record of the current command's inputs."""
    global _guarding
    _inputs.clear()
    _guarding = on


def _remember(path: Path) -> None:
    if _guarding:
        with contextlib.suppress(OSError):
            _inputs.add(path.resolve())


def _refuse_inputs(dests: Iterable[Path]) -> None:
    """Raise InputError before anything is moved if a destination is a known input."""
    for d in dests:
        for inp in _inputs:
            if _same_file(d, inp):
                raise InputError(d, "output would overwrite an input of this command; refusing")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and a.samefile(b))
    except OSError:
        return False


def check_outputs(
    inputs: Iterable[str | os.PathLike], outputs: Iterable[str | os.PathLike]
) -> None:
    """Raise InputError if an output path is one of the inputs or lies in a missing directory."""
    ins = [Path(p) for p in inputs if p is not None]
    for inp in ins:
        _remember(inp)
    for out in outputs:
        out = Path(out)
        for inp in ins:
            if _same_file(out, inp):
                raise InputError(
                    out, "output path is the same as an input; refusing to overwrite it"
                )
        parent = out.resolve().parent
        if not parent.is_dir():
            raise InputError(out, f"output directory {parent} does not exist")


def check_input_file(path: str | os.PathLike, what: str = "input") -> Path:
    """Return Path(path) if it is a readable file, else raise InputError naming it."""
    p = Path(path)
    if not p.exists():
        raise InputError(p, f"{what} does not exist")
    if not p.is_file():
        raise InputError(p, f"{what} is not a regular file")
    if not os.access(p, os.R_OK):
        raise InputError(p, f"{what} is not readable")
    _remember(p)
    return p


def _umask() -> int:
    """The process's file-creation mask (read by setting it and putting it back)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success.

    On any exception (including KeyboardInterrupt) the temporary file is removed
    and ``path`` is left as it was.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent or ".")
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        _refuse_inputs([path])
        with contextlib.suppress(OSError):  # mkstemp made it private: give it a file's usual mode
            os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp_path.unlink()
        raise


class OutputDir:
    """Stage outputs in a hidden temporary directory; move them into place on success.

    Usage::

        with OutputDir(outdir) as tmp:
            write(tmp / "trajectory.tum")
        # now outdir/trajectory.tum exists; nothing was written if the block failed

    Files already in ``outdir`` that the stage does not write are kept. Each file
    is moved with ``os.replace`` (atomic on one file system).
    """

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.tmp: Path | None = None
        self._created = False

    def __enter__(self) -> Path:
        if self.path.exists() and not self.path.is_dir():
            raise InputError(self.path, "output directory path exists and is not a directory")
        parent = self.path.resolve().parent
        if not parent.is_dir():
            raise InputError(self.path, f"parent directory {parent} does not exist")
        self.tmp = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", suffix=".part", dir=parent))
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        assert self.tmp is not None
        try:
            if exc_type is None:
                items = sorted(self.tmp.rglob("*"))
                _refuse_inputs(self.path / i.relative_to(self.tmp) for i in items if i.is_file())
                with _deferred_interrupts():
                    self._move(items)
        finally:
            shutil.rmtree(self.tmp, ignore_errors=True)

    def _move(self, items: list[Path]) -> None:
        """A new directory: one atomic rename of the whole staging directory. An existing
        one: file by file (each ``os.replace`` atomic), Ctrl-C deferred until done."""
        assert self.tmp is not None
        if not self.path.exists():
            os.chmod(self.tmp, 0o777 & ~_umask())  # mkdtemp made it private
            with contextlib.suppress(OSError):
                os.rename(self.tmp, self.path)
                return
        self.path.mkdir(exist_ok=True)
        for item in items:
            dest = self.path / item.relative_to(self.tmp)
            if item.is_dir():
                dest.mkdir(parents=True, exist_ok=True)
            else:
                dest.parent.mkdir(parents=True, exist_ok=True)
                os.replace(item, dest)


@contextlib.contextmanager
def _deferred_interrupts() -> Iterator[None]:
    """Hold SIGINT/SIGTERM while outputs are moved into place, then deliver them, so an
    interruption never leaves a mix of new and old files (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[tuple[int, object]] = []
    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        old[sig] = signal.getsignal(sig)
        signal.signal(sig, lambda signum, frame: caught.append((signum, frame)))
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        for signum, frame in caught[:1]:
            handler = old[signum]
            if callable(handler):
                handler(signum, frame)
            elif handler == signal.SIG_DFL:
                os.kill(os.getpid(), signum)
