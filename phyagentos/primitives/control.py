"""Primitives that touch no target: control flow and bookkeeping inside a skill.

``noop`` succeeds after ``ticks`` ticks and declares no target tool, so a skill made of
it gets an empty TargetToolManifest and its SessionRunner never opens the target: the
cheapest session that still goes through claim, preflight, run, evidence and
verification (used to measure and stress the supervision machinery itself).

``give_way`` fails at once and records nothing: it ends a clean-up branch (a hand raised
back out of what it met) so the selector above moves on with the failure that called for
the clean-up still the session's last.
"""

from __future__ import annotations

from py_trees.common import Status

from .base import Primitive

__all__ = ["GiveWay", "Noop"]


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


class GiveWay(Primitive):
    """Fail at once, recording no failure of its own.

    The last leaf of a clean-up sequence under a selector: after a step failed and what it
    left was undone (the hook's fingers that met the cabinet's body raised back above the
    drawer's front), the sequence fails so the selector's next child runs, and the failure
    the session reports, if nothing after it succeeds, is still the step's own (py_trees'
    selector semantics; :meth:`~phyagentos.primitives.context.SkillContext.fail` keeps the
    last recorded failure).
    """

    TOOLS = ()

    def step(self):
        self.ctx.trace.record("give_way", leaf=self.name)
        return Status.FAILURE
