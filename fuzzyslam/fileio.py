"""Safe output writing: temporary names renamed into place only when complete.

Every command writes through these helpers, so an error or Ctrl-C leaves no
partial file behind and an input is never overwritten.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fnmatch
import os
import shutil
import stat
import sys
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

from fuzzyslam.errors import InputError
from fuzzyslam.interrupts import deferred

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
    inputs: Iterable[str | os.PathLike],
    outputs: Iterable[str | os.PathLike],
    kind: str = "file or directory",
) -> None:
    """Raise InputError if an output path is one of the inputs, lies in a missing
    directory, or exists and is not a ``kind`` (a device, FIFO or socket never is)."""
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
        check_output_target(out, kind)


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


# Write failures that mean the output cannot be completed: one line naming the output.
_WRITE_PROBLEMS = {
    errno.ENOSPC: "no space left on device",
    errno.EDQUOT: "no space left on device (disk quota exceeded)",
    errno.EFBIG: "no space left for it: the file size limit is reached",
    errno.EROFS: "read-only file system",
    errno.EIO: "input/output error",
}
WRITE_ERRNOS = frozenset(_WRITE_PROBLEMS)


def write_error(path: str | os.PathLike, exc: OSError, replaced: bool = False) -> InputError:
    """The one-line error for a failed write of the output ``path`` (the user's name,
    never a temporary one): "cannot write: no space left on device" and the like;
    ``replaced`` says whether other outputs were already in place."""
    problem = _WRITE_PROBLEMS.get(exc.errno or 0) or exc.strerror or type(exc).__name__
    return InputError(
        path, f"cannot write: {problem}" + ("" if replaced else "; nothing was replaced")
    )


def _is_within(name: object, root: Path) -> bool:
    if not isinstance(name, (str, os.PathLike)):
        return False
    try:
        return Path(os.fsdecode(name)).resolve().is_relative_to(root.resolve())
    except (OSError, ValueError):
        return False


def _user_error(exc: BaseException, tmp: Path, dest: Path) -> BaseException | None:
    """``exc`` re-addressed to the user's output ``dest`` if it concerns the temporary
    ``tmp`` (a write failure, or an error naming a file inside it), else None."""
    if isinstance(exc, InputError) and _is_within(exc.path, tmp):
        rel = Path(exc.path).resolve().relative_to(tmp.resolve())
        return InputError(dest / rel if rel.parts else dest, exc.problem)
    if not isinstance(exc, OSError):
        return None
    if exc.filename is not None and _is_within(exc.filename, tmp):
        rel = Path(os.fsdecode(exc.filename)).resolve().relative_to(tmp.resolve())
        return write_error(dest / rel if rel.parts else dest, exc)
    if exc.filename is None and exc.errno in _WRITE_PROBLEMS:
        return write_error(dest, exc)
    return None


def check_output_target(path: str | os.PathLike, kind: str = "file or directory") -> None:
    """Raise InputError unless ``path`` is absent or an existing ``kind`` ("file",
    "directory" or "file or directory"): a device, FIFO or socket is never replaced,
    whatever the user's privileges (os.replace as root would swap the node for a file)."""
    p = Path(path)
    try:
        st = os.stat(p)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise InputError(p, f"cannot use as output: {exc.strerror}") from None
    if stat.S_ISREG(st.st_mode):
        if kind == "directory":
            raise InputError(p, "output directory path exists and is not a directory")
        return
    if stat.S_ISDIR(st.st_mode):
        if kind == "file":
            raise InputError(p, "output path is a directory; refusing to replace it")
        return
    raise InputError(
        p,
        "output path exists and is not a regular file or directory (a device, FIFO or "
        "socket); refusing to replace it",
    )


def _fsync_path(path: Path, directory: bool = False) -> None:
    """Flush ``path`` (a file, or a directory's entries) to the disk."""
    fd = os.open(path, os.O_RDONLY | (os.O_DIRECTORY if directory else 0))
    try:
        os.fsync(fd)
    except OSError as exc:
        if directory and exc.errno in (errno.EINVAL, errno.EBADF):
            return  # some file systems cannot sync a directory
        raise
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` on success
    (:func:`atomic_paths` of one file).

    The temporary file is flushed to the disk (fsync) before the rename, so ``path`` is
    either the old file or the complete new one, also after a crash. On any exception
    (including KeyboardInterrupt) the temporary file is removed and ``path`` is left as
    it was; a write failure (disk full, file size limit) is an InputError naming
    ``path``. A ``path`` that is a device, FIFO, socket or directory is refused.
    """
    with atomic_paths([path]) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_paths(paths: Iterable[str | os.PathLike]) -> Iterator[list[Path]]:
    """Yield a temporary path beside each of ``paths`` (different files); rename them all
    into place only when the block succeeds and every one is complete.

    As :func:`atomic_path` for one file: each is flushed to the disk before the renames,
    which are made together with Ctrl-C held, so the outputs are the old set or the new
    one, never a new file beside an old one. On any exception every temporary file is
    removed and every path left as it was; a write failure is an InputError naming the
    user's path ("nothing was replaced").

    Parameters
    ----------
    paths : iterable of path
        The output files.

    Yields
    ------
    list of Path
        The temporary paths, in the order of ``paths``.
    """
    dests = [Path(p) for p in paths]
    for dest in dests:
        check_output_target(dest, "file")
    tmps: list[Path] = []
    try:
        for dest in dests:
            # Ctrl-C held from the file's making until its name is kept (in tmps: removed
            # on the way out); an interruption between the two left the file behind
            with deferred():
                try:
                    fd, tmp = tempfile.mkstemp(
                        prefix=f".{dest.name}.", suffix=".part", dir=dest.parent or "."
                    )
                except OSError as exc:  # a read-only or full directory: the user's name
                    raise write_error(dest, exc) from exc
                os.close(fd)
                tmps.append(Path(tmp))
        yield list(tmps)
        _refuse_inputs(dests)
        for tmp, dest in zip(tmps, dests, strict=True):
            check_output_target(dest, "file")
            with contextlib.suppress(OSError):  # mkstemp made it private
                os.chmod(tmp, 0o666 & ~_umask())
            _fsync_path(tmp)
        with deferred():
            for tmp, dest in zip(tmps, dests, strict=True):
                os.replace(tmp, dest)
        for parent in dict.fromkeys(d.parent if str(d.parent) else Path(".") for d in dests):
            _fsync_path(parent, directory=True)
    except BaseException as exc:
        for tmp in tmps:
            with contextlib.suppress(OSError):
                tmp.unlink()
        for tmp, dest in zip(tmps, dests, strict=False):  # the user's name of the file
            mapped = _user_error(exc, tmp, dest)
            if mapped is not None:
                raise mapped from exc
        raise


class OutputDir:
    """Stage outputs in a hidden temporary directory; replace the output directory with
    it, whole, on success.

    Usage::

        with OutputDir(outdir) as tmp:
            write(tmp / "trajectory.tum")
        # now outdir/trajectory.tum exists; nothing was written if the block failed

    Files already in ``outdir`` that the stage does not write are kept (hard-linked into
    the new directory), except those matching ``owns`` (names the stage may write, e.g.
    ``heading_fixes.csv``: a stale one would mix runs). The finished directory is flushed
    to the disk and exchanged with the old one in one atomic step (``renameat2``
    RENAME_EXCHANGE; two renames with Ctrl-C held where that is missing), so ``outdir``
    is always the old set of files or the new one, never a mix. A write failure is one
    InputError naming the user's file, never the temporary name.
    """

    def __init__(self, path: str | os.PathLike, owns: Iterable[str] = ()) -> None:
        self.path = Path(path)
        self.owns = tuple(owns)
        self.tmp: Path | None = None

    def _where(self) -> Path:
        """The directory the staging directory goes into (InputError when the output
        path is not a directory or its parent is missing)."""
        check_output_target(self.path, "directory")
        real = self.path.resolve()
        parent = real.parent
        if not parent.is_dir():
            raise InputError(self.path, f"parent directory {parent} does not exist")
        # a directory filled in place (a mount point, the working directory) is staged
        # inside itself: its files are then renamed within one file system
        return real if real.is_dir() and _in_place_only(real) else parent

    def check(self) -> None:
        """Raise the error that entering would (the path not a directory, its parent
        missing, a staging directory that cannot be made there), staging nothing: for a
        stage that enters only after its work (``map``, ``evaluate``), so that an unusable
        output is said before the work, as ``run``'s, which enters first."""
        where = self._where()
        try:
            with deferred():  # Ctrl-C held: the probe is never left behind
                os.rmdir(
                    tempfile.mkdtemp(prefix=f".{self.path.resolve().name}.", suffix=".part",
                                     dir=where)
                )  # fmt: skip
        except OSError as exc:  # read-only or full: as __enter__ says it
            raise write_error(self.path, exc) from exc

    def __enter__(self) -> Path:
        where = self._where()
        real = self.path.resolve()
        try:
            # Ctrl-C held from the folder's making until its name is kept; __exit__ does
            # not run for an exception raised here, so a held one removes the folder
            with deferred():
                self.tmp = Path(
                    tempfile.mkdtemp(prefix=f".{real.name}.", suffix=".part", dir=where)
                )
        except OSError as exc:  # read-only or full: the user's name, not the temporary one
            raise write_error(self.path, exc) from exc
        except BaseException:
            if self.tmp is not None:
                shutil.rmtree(self.tmp, ignore_errors=True)
                self.tmp = None
            raise
        return self.tmp

    def __exit__(self, exc_type, exc, tb) -> None:
        assert self.tmp is not None
        try:
            if exc_type is None:
                try:
                    items = sorted(self.tmp.rglob("*"))
                    dests = [self.path / i.relative_to(self.tmp) for i in items if i.is_file()]
                    _refuse_inputs(dests)
                    check_output_target(self.path, "directory")
                    for d in dests:
                        check_output_target(d, "file")
                    self._complete()
                    with deferred():
                        self._move(items)
                except BaseException as err:
                    mapped = _user_error(err, self.tmp, self.path)
                    if mapped is not None:
                        raise mapped from err
                    raise
            elif exc is not None:
                mapped = _user_error(exc, self.tmp, self.path)
                if mapped is not None:
                    raise mapped from exc
        finally:
            shutil.rmtree(self.tmp, ignore_errors=True)

    def _complete(self) -> None:
        """Carry the old directory's other files into the new one (hard links, or copies
        where links are refused) and flush every file and directory to the disk."""
        assert self.tmp is not None
        real = self.path.resolve()
        if real.is_dir() and not _in_place_only(real):
            for old in sorted(real.rglob("*")):
                rel = old.relative_to(real)
                new = self.tmp / rel
                if new.exists() or new.is_symlink() or _owned(rel, self.owns):
                    continue
                if old.is_dir() and not old.is_symlink():
                    new.mkdir(parents=True, exist_ok=True)
                    continue
                new.parent.mkdir(parents=True, exist_ok=True)
                try:
                    os.link(old, new, follow_symlinks=False)
                except OSError:
                    shutil.copy2(old, new, follow_symlinks=False)
        os.chmod(self.tmp, 0o777 & ~_umask())  # mkdtemp made it private
        for item in sorted(self.tmp.rglob("*"), reverse=True):
            if not item.is_symlink():
                _fsync_path(item, directory=item.is_dir())
        _fsync_path(self.tmp, directory=True)

    def _move(self, items: list[Path]) -> None:
        """Put the staging directory in place of ``self.path``: one rename for a new
        directory, an atomic exchange for an existing one (the old one is then removed).
        The working directory or a mount point cannot be swapped: its files are replaced
        one by one from a staging directory inside it (Ctrl-C is held meanwhile), and the
        stage's optional outputs that this run did not write are removed."""
        assert self.tmp is not None
        real = self.path.resolve()
        if not real.exists():
            os.rename(self.tmp, real)
        elif _in_place_only(real):
            rels = {item.relative_to(self.tmp) for item in items}
            for item in items:
                dest = real / item.relative_to(self.tmp)
                if item.is_dir():
                    dest.mkdir(parents=True, exist_ok=True)
                else:
                    dest.parent.mkdir(parents=True, exist_ok=True)
                    os.replace(item, dest)
            for old in sorted(real.rglob("*")):  # the stage's stale optional outputs
                rel = old.relative_to(real)
                if old.is_relative_to(self.tmp.resolve()):
                    continue
                if rel not in rels and old.is_file() and _owned(rel, self.owns):
                    old.unlink()
        elif not _exchange(self.tmp, real):
            old = Path(tempfile.mkdtemp(prefix=f".{real.name}.", suffix=".old", dir=real.parent))
            os.rmdir(old)
            os.rename(real, old)
            try:
                os.rename(self.tmp, real)
            except BaseException:
                os.rename(old, real)
                raise
            shutil.rmtree(old, ignore_errors=True)
        # after an exchange self.tmp holds the old directory: __exit__ removes it
        _fsync_path(real.parent, directory=True)


def _in_place_only(path: Path) -> bool:
    """True if ``path`` must not be renamed: a mount point, or the working directory
    or one of its parents (the shell would be left in a removed directory)."""
    try:
        cwd = Path.cwd().resolve()
    except OSError:
        return True
    return os.path.ismount(path) or cwd == path or cwd.is_relative_to(path)


def _owned(rel: Path, patterns: tuple[str, ...]) -> bool:
    return any(fnmatch.fnmatch(rel.as_posix(), p) for p in patterns)


_RENAME_EXCHANGE = 2


def _exchange(a: Path, b: Path) -> bool:
    """Swap the directories ``a`` and ``b`` atomically (Linux renameat2); False where
    the call is unavailable or refused (then the caller falls back to two renames)."""
    if sys.platform != "linux":
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd = -100
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), _RENAME_EXCHANGE)
    return rc == 0
