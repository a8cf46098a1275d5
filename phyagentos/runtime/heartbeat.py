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

One more cell, after the slots, is not a heartbeat: the ``time.monotonic()`` at which
the runner started the session's execution clock (:meth:`Heartbeats.start_execution`).
The supervisor's execution deadline counts from it, as the runner's own does, so a
session set up slowly (a target built, a scene perceived, on a loaded machine) is not
cancelled for time it never spent executing.
"""

from __future__ import annotations

import time
from typing import Any

__all__ = ["SLOTS", "ARRAY_LENGTH", "Heartbeats"]

#: Heartbeat slots, in the order of the shared array.
SLOTS: tuple[str, ...] = ("runner", "target", "policy")
_INDEX = {name: i for i, name in enumerate(SLOTS)}
_EXECUTION = len(SLOTS)
#: Length of the shared array: the slots, then the execution-clock start.
ARRAY_LENGTH = len(SLOTS) + 1


class Heartbeats:
    """Monotonic heartbeat stamps in shared memory.

    Args:
        array: a ``multiprocessing`` ``RawArray('d', ARRAY_LENGTH)`` shared with the
            runner process (default: a process-local array, for in-process use).
    """

    def __init__(self, array: Any | None = None) -> None:
        if array is None:
            import multiprocessing  # noqa: PLC0415

            array = multiprocessing.RawArray("d", ARRAY_LENGTH)
        if len(array) != ARRAY_LENGTH:
            raise ValueError(f"heartbeat array needs {ARRAY_LENGTH} cells (the slots {', '.join(SLOTS)}, then the "
                             f"execution-clock start), got {len(array)}")
        self.array = array

    def beat(self, slot: str = "runner", now: float | None = None) -> None:
        """Stamp ``slot`` (one of :data:`SLOTS`) with ``now`` (default ``time.monotonic()``)."""
        self.array[_INDEX[slot]] = time.monotonic() if now is None else now

    def reset(self) -> None:
        """Disarm every slot and forget the execution-clock start (start of a session)."""
        for i in range(ARRAY_LENGTH):
            self.array[i] = 0.0

    def start_execution(self, now: float | None = None) -> None:
        """Record ``now`` (``time.monotonic()``, s) as the session's execution-clock start."""
        self.array[_EXECUTION] = time.monotonic() if now is None else now

    def execution_started_at(self) -> float | None:
        """The ``time.monotonic()`` (s) at which the session's execution clock started,
        or None while the runner is still setting the session up."""
        stamp = self.array[_EXECUTION]
        return stamp if stamp > 0.0 else None

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
