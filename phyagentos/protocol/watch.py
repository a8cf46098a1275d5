"""Event-driven wake-ups on workspace changes, with a bounded polling fallback.

Both planes sleep until the workspace changes instead of polling in a loop. A
``watchdog`` observer (inotify on Linux) watches the directories that matter
(``sessions/``, ``sessions/.index/``, ...) and, optionally, individual files of the
workspace root (``RUNTIME_SIGNAL.md``); every relevant event makes the watcher's
:meth:`fileno` readable, so the owner can ``select`` on it together with other
descriptors (a runner pipe). Protocol writes are atomic renames, so only
create/move/delete events are observed; modify/open/close noise never wakes anyone.

watchdog holds an ``IN_MOVED_FROM`` event for half a second, waiting for the
``IN_MOVED_TO`` it may pair with, and its event queue delivers nothing else meanwhile
(``DelayedQueue.get`` sleeps out the head's delay even once it was paired). A file moved
out of a watched directory (``SessionArchive.archive`` moves a session file into its day
directory) thus held every later event of that directory back by 0.5 s, and a rename
inside it did whenever the observer's thread ran between the two halves of the rename (2
of 4,300 atomic writes in loops). This module sets that pairing delay to zero: a
move then wakes the owner at once, as a deletion and a creation or as one move, which
is all a wake-up needs.

If the observer cannot start (no inotify, watch limit reached) the watcher runs in
``polling`` mode: :meth:`wait` simply times out, and callers bound every wait by
their poll interval, so a missed event costs at most one interval either way.
"""

from __future__ import annotations

import logging
import os
import select
import socket
import threading
from pathlib import Path
from typing import Any, Iterable

__all__ = ["WorkspaceWatcher"]

log = logging.getLogger(__name__)


class _StopRaceFilter(logging.Filter):
    """watchdog logs an ERROR when an event arrives while its observer is being
    stopped; for a watcher that is closing on purpose that is noise, not an error."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "called when the thread is inactive" not in record.getMessage()


logging.getLogger("watchdog.observers.inotify").addFilter(_StopRaceFilter())


def _no_move_pairing_delay() -> None:
    """Set watchdog's move-pairing delay to zero (see the module docstring): the class
    attribute ``delay`` its inotify emitter reads when it builds its queue,
    ``InotifyMoveEventGrouper`` since watchdog 7, ``InotifyBuffer`` before."""
    holder: Any
    try:
        from watchdog.observers.inotify_move_event_grouper import (  # noqa: PLC0415
            InotifyMoveEventGrouper,
        )
        holder = InotifyMoveEventGrouper
    except ImportError:
        try:
            from watchdog.observers.inotify_buffer import InotifyBuffer  # noqa: PLC0415
            holder = InotifyBuffer
        except ImportError:  # not Linux: no inotify emitter
            return
    holder.delay = 0.0


def _stop_observer(observer) -> None:
    observer.stop()
    observer.join(timeout=2)


class WorkspaceWatcher:
    """Wakes its owner when watched workspace paths change.

    Args:
        root: the workspace root.
        dirs: directories (relative to ``root``) whose entries are watched; created if missing.
        files: file names in ``root`` itself that are watched (e.g. ``RUNTIME_SIGNAL.md``).
        inotify: False forces polling mode (benchmarks compare both).
    """

    def __init__(self, root: str | os.PathLike[str], *, dirs: Iterable[str] = ("sessions", "sessions/.index"),
                 files: Iterable[str] = (), inotify: bool = True) -> None:
        self.root = Path(root)
        self._rsock, self._wsock = socket.socketpair()
        self._rsock.setblocking(False)
        self._wsock.setblocking(False)
        self._observer: Any = None  # a watchdog Observer once started
        self.mode = "polling"
        self._files = {self.root / f for f in files}
        if inotify:
            self._start([self.root / d for d in dirs])

    def _start(self, dirs: list[Path]) -> None:
        try:
            from watchdog.events import (  # noqa: PLC0415 - optional at import time
                FileCreatedEvent,
                FileDeletedEvent,
                FileMovedEvent,
                FileSystemEventHandler,
            )
            from watchdog.observers import Observer  # noqa: PLC0415
        except ImportError:  # pragma: no cover - watchdog is a dependency
            log.warning("watchdog unavailable; falling back to polling")
            return
        _no_move_pairing_delay()
        watcher = self

        class _Handler(FileSystemEventHandler):
            def __init__(self, only: set[Path] | None) -> None:
                self.only = only

            def on_any_event(self, event) -> None:
                if self.only is not None:
                    names = {Path(os.fsdecode(event.src_path))}
                    if getattr(event, "dest_path", None):
                        names.add(Path(os.fsdecode(event.dest_path)))
                    if not names & self.only:
                        return
                watcher.notify()

        kinds = [FileCreatedEvent, FileMovedEvent, FileDeletedEvent]
        try:
            observer = Observer()
            for d in dirs:
                d.mkdir(parents=True, exist_ok=True)
                observer.schedule(_Handler(None), str(d), recursive=False, event_filter=kinds)
            if self._files:
                observer.schedule(_Handler(self._files), str(self.root), recursive=False, event_filter=kinds)
            observer.daemon = True
            observer.start()
        except OSError as exc:  # e.g. inotify watch or instance limit reached
            log.warning("cannot watch %s (%s); falling back to polling", self.root, exc)
            return
        self._observer = observer
        self.mode = "inotify"

    def fileno(self) -> int:
        """Readable when a watched path changed (or :meth:`notify` was called)."""
        return self._rsock.fileno()

    def notify(self) -> None:
        """Wake the owner. Lock-free, so safe from other threads and Python signal handlers;
        a full socket buffer already means a wake-up is pending."""
        try:
            self._wsock.send(b"!")
        except (BlockingIOError, OSError):
            pass

    def clear(self) -> None:
        """Forget pending wake-ups; call before re-reading the workspace."""
        try:
            while self._rsock.recv(4096):
                pass
        except (BlockingIOError, OSError):
            pass

    def wait(self, timeout: float | None) -> bool:
        """Block until a change or ``timeout`` seconds; True if woken by a change."""
        ready, _, _ = select.select([self._rsock], [], [], timeout)
        return bool(ready)

    def close(self, *, wait: bool = False) -> None:
        """Stop watching and close the wake-up socket.

        The observer is stopped on a daemon thread unless ``wait``: ``stop`` joins
        watchdog's inotify emitter, which sleeps out its move-pairing delay on an
        unmatched ``IN_MOVED_FROM`` (a session file moved into its archive directory,
        which is not watched; 0.5 s unless :func:`_no_move_pairing_delay` could set it
        to zero). Nothing is delivered after this call returns:
        the handler's wake-up goes to a closed socket and is dropped.
        """
        observer, self._observer = self._observer, None
        for s in (self._rsock, self._wsock):
            try:
                s.close()
            except OSError:
                pass
        if observer is None:
            return
        if wait:
            _stop_observer(observer)
        else:
            threading.Thread(target=_stop_observer, args=(observer,), name="phyagentos-watch-stop",
                             daemon=True).start()

    def __enter__(self) -> WorkspaceWatcher:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
