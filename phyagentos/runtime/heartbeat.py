"""Heartbeats from the runner, the target and the policy, shared with the supervisor.

The runner process stamps ``time.monotonic()`` into a small shared-memory array: one
store per beat, no system call, no file write, so beating on every behaviour-tree
tick costs nothing measurable. ``CLOCK_MONOTONIC`` is system-wide on Linux, so the
supervisor (another process) compares stamps against its own ``time.monotonic()``.

Slots: ``runner`` (stamped by the SessionRunner after each tick and while writing
evidence), ``target`` (after each tick in which the target answered; for a remote
robot, its driver's link heartbeat) and ``policy`` (the PolicySkillRuntime, after
each inference round trip). A slot is *armed* by its first beat of a session; the
supervisor only judges armed slots, and a stale armed slot ends the session with
``heartbeat.<slot>`` (docs/ERRORS.md).
"""

from __future__ import annotations

import time
from typing import Any

__all__ = ["SLOTS", "Heartbeats"]

#: Heartbeat slots, in the order of the shared array.
SLOTS: tuple[str, ...] = ("runner", "target", "policy")
_INDEX = {name: i for i, name in enumerate(SLOTS)}


class Heartbeats:
    """Monotonic heartbeat stamps in shared memory.

    Args:
        array: a ``multiprocessing`` ``RawArray('d', len(SLOTS))`` shared with the
            runner process (default: a process-local array, for in-process use).
    """

    def __init__(self, array: Any | None = None) -> None:
        if array is None:
            import multiprocessing  # noqa: PLC0415

            array = multiprocessing.RawArray("d", len(SLOTS))
        if len(array) != len(SLOTS):
            raise ValueError(f"heartbeat array needs {len(SLOTS)} slots ({', '.join(SLOTS)}), got {len(array)}")
        self.array = array

    def beat(self, slot: str = "runner", now: float | None = None) -> None:
        """Stamp ``slot`` (one of :data:`SLOTS`) with ``now`` (default ``time.monotonic()``)."""
        self.array[_INDEX[slot]] = time.monotonic() if now is None else now

    def reset(self) -> None:
        """Disarm every slot (start of a session)."""
        for i in range(len(SLOTS)):
            self.array[i] = 0.0

    def age(self, slot: str, now: float | None = None) -> float | None:
        """Seconds since ``slot`` last beat, or None if it has not beaten since :meth:`reset`."""
        stamp = self.array[_INDEX[slot]]
        if stamp <= 0.0:
            return None
        return (time.monotonic() if now is None else now) - stamp

    def stale(self, timeout_s: float, now: float | None = None) -> str | None:
        """The first armed slot older than ``timeout_s`` seconds, or None."""
        now = time.monotonic() if now is None else now
        for slot in SLOTS:
            age = self.age(slot, now)
            if age is not None and age > timeout_s:
                return slot
        return None
