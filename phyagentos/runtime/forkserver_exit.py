"""Imported only by the runner forkserver (first in its preload list): its interpreter
exits at once when its parent goes away.

The forkserver holds MuJoCo, SciPy, toppra, mink and the rest of the
runtime; tearing that interpreter down takes seconds on a loaded machine, and since
the forkserver shares the command's stdout and stderr, a caller reading them (a pipe,
``subprocess.run``) waits for it. It owns nothing that needs tearing down (no files,
no locks: runners are its children and exit by themselves), so it skips the teardown.
Forked runners are unaffected: multiprocessing ends them with ``os._exit`` anyway.
"""

from __future__ import annotations

import atexit
import os
import sys

__all__: list[str] = []


def _exit_now() -> None:
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(0)


atexit.register(_exit_now)
