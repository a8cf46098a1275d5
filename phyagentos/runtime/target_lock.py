"""Who may move a target: an OS lock held by the process that actuates it.

One session at a time may actuate a target (a robot cannot run two episodes at
once, and a simulated target's world state is one file). The *runner* process
takes ``.locks/target-<name>.lock`` (``flock``) before a session is claimed and keeps
it until the session's runtime phase is written back. Because the kernel drops an
``flock`` when its process dies, the lock is free exactly when nobody can still be
moving the target: a runner orphaned by a dead supervisor keeps it until it has
halted and exited.

``targets/<name>/inflight.yaml`` names the session that may be actuating the target
(written, fsynced, before the ``start`` transition; removed after the runtime phase
is written back). Whoever next takes the lock and finds the marker knows that
session ended abnormally and recovers it *before anything moves again*.

Linux/POSIX only (``fcntl.flock``); the workspace must be on a local filesystem.
"""

from __future__ import annotations

import fcntl
import logging
import os
import time
from pathlib import Path
from typing import Any

import yaml

from phyagentos.errors import TargetError
from phyagentos.protocol.atomic import _fsync_dir, atomic_write_text
from phyagentos.protocol.codec import dump_yaml
from phyagentos.yamlsource import load_yaml

__all__ = ["TargetLock", "INFLIGHT_FILE", "write_marker", "read_marker", "clear_marker"]

logger = logging.getLogger(__name__)

INFLIGHT_FILE = "inflight.yaml"


class TargetLock:
    """The exclusive actuation lock of one target.

    Args:
        locks_dir: the workspace's ``.locks/`` directory.
        target: target name (TARGETS.md).
    """

    def __init__(self, locks_dir: str | os.PathLike[str], target: str) -> None:
        self.target = target
        self.path = Path(locks_dir) / f"target-{target}.lock"
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def try_acquire(self) -> bool:
        """Take the lock if it is free; True on success (also if already held here)."""
        if self._fd is not None:
            return True
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            return False
        except BaseException:
            os.close(fd)
            raise
        self._fd = fd
        return True

    def acquire(self, timeout_s: float, *, poll_s: float = 0.02) -> bool:
        """Wait up to ``timeout_s`` seconds for the lock; True if taken."""
        deadline = time.monotonic() + timeout_s
        while not self.try_acquire():
            if time.monotonic() >= deadline:
                return False
            time.sleep(poll_s)
        return True

    def release(self) -> None:
        """Drop the lock (closing the descriptor releases the ``flock``)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def _marker_path(targets_dir: str | os.PathLike[str], target: str) -> Path:
    return Path(targets_dir) / target / INFLIGHT_FILE


def write_marker(targets_dir: str | os.PathLike[str], target: str, *, session_id: str, token: str,
                 owner: str) -> None:
    """Record (durably) that ``session_id`` may actuate ``target`` from now on."""
    path = _marker_path(targets_dir, target)
    path.parent.mkdir(parents=True, exist_ok=True)
    # rendered by the codec's block emitter: a tenth of yaml.safe_dump's time, before the preflight's reply
    atomic_write_text(path, dump_yaml({"owner": owner, "session_id": session_id, "since": time.time(), "token": token}))


def read_marker(targets_dir: str | os.PathLike[str], target: str) -> dict[str, Any] | None:
    """The in-flight marker of ``target`` (``session_id``, ``token``, ``owner``, ``since``), or None."""
    path = _marker_path(targets_dir, target)
    try:
        data = load_yaml(path.read_text(encoding="utf-8"), path=path, error=TargetError)  # bounded
    except FileNotFoundError:
        return None
    except (yaml.YAMLError, TargetError, UnicodeDecodeError):
        logger.warning("unreadable in-flight marker %s; treating it as naming no session", path)
        return {"session_id": None, "token": None, "owner": None}
    return data if isinstance(data, dict) else None


def clear_marker(targets_dir: str | os.PathLike[str], target: str, *, session_id: str | None = None) -> None:
    """Remove the marker (only if it names ``session_id``, when given)."""
    path = _marker_path(targets_dir, target)
    if session_id is not None:
        current = read_marker(targets_dir, target)
        if current is not None and current.get("session_id") not in (None, session_id):
            return
    try:
        path.unlink()
    except FileNotFoundError:
        return
    _fsync_dir(path.parent)
