"""``python -m fuzzyslam``: the CLI. A Ctrl-C while its modules are still loading exits
as one later does (130, one line), not as an uncaught KeyboardInterrupt."""

import os
import sys

try:
    from fuzzyslam.cli import entry
    from fuzzyslam.errors import EXIT_INTERRUPTED
except KeyboardInterrupt:
    sys.stderr.write("fuzzyslam: interrupted; no partial outputs were kept\n")
    sys.stderr.flush()
    os._exit(130)

try:
    entry()
except KeyboardInterrupt:  # between main's own handlers and its exit
    sys.stderr.write("fuzzyslam: interrupted; no partial outputs were kept\n")
    sys.stderr.flush()
    os._exit(EXIT_INTERRUPTED)
