"""Workspace locks: an exclusive ``flock(2)`` on one file under ``ws/.locks/``.

A :class:`WorkspaceLock` excludes other processes (the kernel's ``flock``) and other
threads of this process (each thread locks through its own open file description, and
``flock`` locks on two descriptions of one file conflict even within a process), and is
re-entrant within a thread: a caller that holds a session's lock may call a method that
takes it again. :func:`workspace_lock` returns the one object of a lock file in this
process, so re-entrancy also holds across :class:`~phyagentos.protocol.Workspace`
objects of the same directory.

Waiting blocks in the kernel (``flock`` without ``LOCK_NB``, the GIL released): the
waiter wakes when the holder releases, with no polling period added. A finite
``timeout`` polls every millisecond instead. The kernel drops the lock when its holder
dies, so a killed writer never leaves a workspace locked.

Why not ``filelock``: one acquire-release cycle of its ``FileLock`` costs about 0.25 ms
of Python (fork tracking, singleton bookkeeping; measured with filelock 4.2.11), and a
hand-off from one session to the next takes a dozen of these locks across three
processes; this module does the same job in about 0.02 ms. Linux/POSIX only, like
:mod:`phyagentos.runtime.target_lock`; the workspace must be on a local filesystem.
"""

from __future__ import annotations

import fcntl
import os
import threading
import time
import weakref

from phyagentos.errors import LockTimeout

__all__ = ["WorkspaceLock", "workspace_lock"]

#: How often a waiter with a finite timeout retries a busy lock (s).
_POLL_S = 0.001

_OPEN_FLAGS = os.O_RDWR | os.O_CREAT | os.O_CLOEXEC

_REGISTRY: weakref.WeakValueDictionary[str, WorkspaceLock] = weakref.WeakValueDictionary()
_REGISTRY_GUARD = threading.Lock()
#: Locks some thread holds: kept alive while held, so a caller that keeps no reference
#: between acquire and release still finds the same object (and its hold) again.
_HELD: set[WorkspaceLock] = set()


class _Held(threading.local):
    """This thread's hold on one lock: its descriptor, nesting depth and process."""

    fd: int | None = None
    depth: int = 0
    pid: int = 0


class WorkspaceLock:
    """The exclusive lock of one lock file (get it with :func:`workspace_lock`).

    Use it as a context manager or with :meth:`acquire` / :meth:`release`.

    Args:
        path: the lock file (created with its directory if missing, never removed; its
            content is unused).
    """

    __slots__ = ("path", "_held", "__weakref__")

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = os.fspath(path)
        self._held = _Held()

    def __repr__(self) -> str:
        return f"WorkspaceLock({self.path!r})"

    def _state(self) -> _Held:
        held = self._held
        if held.depth and held.pid != os.getpid():
            # Inherited through fork from a thread that held it: the parent's hold, not ours
            # (the descriptor stays open here; closing it would not release the parent).
            held.fd, held.depth = None, 0
        return held

    @property
    def held(self) -> bool:
        """Whether the calling thread holds the lock."""
        return self._state().depth > 0

    def acquire(self, timeout: float | None = None) -> WorkspaceLock:
        """Take the lock (again, if this thread holds it already); returns ``self``.

        Args:
            timeout: ``None`` waits as long as it takes; otherwise the longest wait in s
                (``0``: one try).

        Raises:
            LockTimeout: the lock stayed busy for ``timeout`` s (also a ``TimeoutError``).
            OSError: the lock file cannot be opened or its directory made.
        """
        held = self._state()
        if held.depth:
            held.depth += 1
            return self
        try:
            fd = os.open(self.path, _OPEN_FLAGS, 0o644)
        except FileNotFoundError:  # the lock directory is made on first use (and again if removed)
            os.makedirs(os.path.dirname(self.path), exist_ok=True)
            fd = os.open(self.path, _OPEN_FLAGS, 0o644)
        try:
            if timeout is None:
                fcntl.flock(fd, fcntl.LOCK_EX)
            else:
                deadline = time.monotonic() + timeout
                while True:
                    try:
                        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                        break
                    except BlockingIOError:
                        if time.monotonic() >= deadline:
                            raise LockTimeout(f"lock {self.path} still held by another process or thread "
                                              f"after {timeout} s") from None
                        time.sleep(_POLL_S)
        except BaseException:
            os.close(fd)
            raise
        held.fd, held.depth, held.pid = fd, 1, os.getpid()
        _HELD.add(self)
        return self

    def release(self) -> None:
        """Give up one level of this thread's hold; the last one unlocks.

        Raises:
            RuntimeError: this thread does not hold the lock.
        """
        held = self._state()
        if not held.depth:
            raise RuntimeError(f"release of {self.path}, which this thread does not hold")
        held.depth -= 1
        if held.depth == 0:
            fd, held.fd = held.fd, None
            assert fd is not None  # depth > 0 means a descriptor is held
            _HELD.discard(self)
            os.close(fd)  # closing the only descriptor of this open file releases the flock

    def __enter__(self) -> WorkspaceLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


def workspace_lock(path: str | os.PathLike[str]) -> WorkspaceLock:
    """The one :class:`WorkspaceLock` of the lock file at ``path`` in this process.

    ``path`` should be canonical (e.g. under a directory passed through
    :func:`os.path.realpath`): two spellings of one file would be two objects, and a
    thread nesting them would wait for itself.
    """
    key = os.fspath(path)
    lock = _REGISTRY.get(key)
    if lock is None:
        with _REGISTRY_GUARD:
            lock = _REGISTRY.get(key)
            if lock is None:
                lock = _REGISTRY[key] = WorkspaceLock(key)
    return lock
