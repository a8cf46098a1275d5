"""Presence of fleet peers through zenoh liveliness tokens.

Every edge and agent declares ``P/<edge|agent>/<name>/alive`` for as long as its session
lives; a partition or a crash makes the token vanish at every peer on the other side
(zenoh's liveliness), which is how an edge learns it lost its agent.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

__all__ = ["Presence"]


class Presence:
    """Names alive now, and since when a name is gone (monotonic seconds).

    Args:
        on_change: called with ``(name, alive)`` after each change (zenoh's thread).
    """

    def __init__(self, on_change: Callable[[str, bool], None] | None = None) -> None:
        self._alive: set[str] = set()
        self._gone_at: dict[str, float] = {}
        self._lock = threading.Lock()
        self._on_change = on_change
        self.changed = threading.Condition(self._lock)

    def update(self, key: str, alive: bool) -> None:
        """Feed a liveliness change of ``key`` (``.../<name>/alive``)."""
        name = key.rstrip("/").split("/")[-2]
        with self._lock:
            if alive:
                self._alive.add(name)
                self._gone_at.pop(name, None)
            else:
                self._alive.discard(name)
                self._gone_at[name] = time.monotonic()
            self.changed.notify_all()
        if self._on_change is not None:
            self._on_change(name, alive)

    def alive(self, name: str) -> bool:
        with self._lock:
            return name in self._alive

    def names(self) -> set[str]:
        with self._lock:
            return set(self._alive)

    def gone_for(self, name: str) -> float | None:
        """Seconds since ``name`` vanished (None while alive; ``inf`` if never seen)."""
        with self._lock:
            if name in self._alive:
                return None
            at = self._gone_at.get(name)
            return float("inf") if at is None else time.monotonic() - at

    def wait_for(self, pred: Callable[[set[str]], bool], timeout_s: float) -> bool:
        """Block until ``pred(alive names)`` holds or ``timeout_s`` passed."""
        deadline = time.monotonic() + timeout_s
        with self._lock:
            while not pred(set(self._alive)):
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self.changed.wait(left)
            return True
