"""Errors and the exit-code scheme shared by every command.

Exit codes:
    0   success
    1   internal failure (a bug): one line, ``--debug`` shows the traceback
    2   usage error (bad option or argument, from click)
    3   bad input: a file or config that is missing, malformed or inconsistent
    130 interrupted (Ctrl-C); no partial outputs are left behind
    143 terminated (SIGTERM); likewise
"""

from __future__ import annotations

from fuzzyslam.summary import path_text

EXIT_OK = 0
EXIT_INTERNAL = 1
EXIT_USAGE = 2
EXIT_INPUT = 3
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


class FuzzyslamError(Exception):
    """Base class of errors that are reported as one clear line."""

    exit_code = EXIT_INPUT


class InputError(FuzzyslamError):
    """A file given to a command is missing, unreadable or inconsistent."""

    def __init__(self, path: object, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        # the message shows the path as the text outputs do (summary.path_text: valid
        # Unicode under any locale); ``path`` keeps it as the system gave it
        super().__init__(f"{path_text(self.path)}: {problem}")

    def __reduce__(self) -> tuple:
        """Pickled as (type, path, problem): the exception comes back whole from a child
        process (``slam/prefetch.py``); ``Exception``'s own pickling would call
        ``__init__`` with the one-line message alone."""
        return type(self), (self.path, self.problem)


class ConfigError(InputError):
    """A configuration file has an unknown key, a wrong type or an out-of-range value."""


class UsageError(FuzzyslamError):
    """Arguments of a stage that do not go together (exit 2, as click's usage errors; the
    CLI shows it as one)."""

    exit_code = EXIT_USAGE
