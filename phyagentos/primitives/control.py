"""Primitives that touch no target: control flow and bookkeeping inside a skill.

``noop`` succeeds after ``ticks`` ticks and declares no target tool, so a skill made of
it gets an empty TargetToolManifest and its SessionRunner never opens the target: the
cheapest session that still goes through claim, preflight, run, evidence and
verification (used to measure and stress the supervision machinery itself).
"""

from __future__ import annotations

from py_trees.common import Status

from .base import Primitive

__all__ = ["Noop"]


class Noop(Primitive):
    """Succeed after ``ticks`` ticks (>= 1) without touching the target."""

    TOOLS = ()

    def __init__(self, name: str, *, ticks: int = 1):
        super().__init__(name)
        if not isinstance(ticks, int) or isinstance(ticks, bool) or ticks < 1:
            raise ValueError(f"ticks must be an integer >= 1, got {ticks!r}")
        self.ticks = ticks

    def on_enter(self):
        self._left = self.ticks

    def step(self):
        self._left -= 1
        self.ctx.trace.record("noop", left=self._left)
        return Status.RUNNING if self._left > 0 else Status.SUCCESS
