"""BuiltinSkillRuntime: runs a skill as a py_trees behaviour tree against a target.

The runtime builds the skill's tree with the session's parameters, sets it up
with the session's :class:`~phyagentos.primitives.context.SkillContext`, and ticks it
until the root succeeds or fails. Between ticks it checks the cancel token and the
execution deadline, so cancellation is preemptive at tick granularity (long
primitives such as trajectory execution advance one control period per tick).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Callable

import py_trees

from phyagentos.primitives import PRIMITIVES
from phyagentos.primitives.context import SkillContext

from .skills import SkillRegistry
from .trees import TreeLibrary

__all__ = ["BuiltinSkillRuntime", "RunOutcome"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunOutcome:
    """How the runtime ended (not whether the task succeeded: that is the verdict).

    Attributes:
        status: ``completed`` (root SUCCESS), ``failed`` (root FAILURE),
            ``cancelled``, ``timed_out`` or ``error`` (an exception escaped).
        error_code: taxonomy code of the failure (e.g. ``planning.failed``), if any.
        failed_primitive: name of the leaf that failed last, if any.
        message: human explanation.
        ticks: number of root ticks.
    """

    status: str
    error_code: str | None = None
    failed_primitive: str | None = None
    message: str = ""
    ticks: int = 0


class BuiltinSkillRuntime:
    """Executes skills whose manifests name ``runtime: builtin``.

    Args:
        skills: the skill manifests.
        trees: the tree library (primitives registered).
    """

    name = "builtin"

    def __init__(self, skills: SkillRegistry, trees: TreeLibrary):
        self.skills = skills
        self.trees = trees

    @classmethod
    def from_dirs(cls, skills_dir, trees_dir) -> "BuiltinSkillRuntime":
        return cls(SkillRegistry(skills_dir), TreeLibrary(trees_dir, PRIMITIVES))

    def build(self, skill: str, params) -> py_trees.behaviour.Behaviour:
        """Build a fresh tree for ``skill`` (raises SkillError on bad input)."""
        manifest = self.skills.get(skill)
        return self.trees.build(manifest.tree, params)

    def run(self, skill: str, ctx: SkillContext, *, deadline: float, heartbeat: Callable[[], None] | None = None) -> RunOutcome:
        """Tick ``skill``'s tree to completion, cancellation or ``deadline``.

        Args:
            skill: skill name.
            ctx: the session's context (target, params, trace ...).
            deadline: ``time.monotonic()`` value after which the run is timed out.
            heartbeat: called after every tick.

        Calls ``ctx.actuation_starts()`` once the tree is built and set up, right before
        the first tick.
        """
        root = self.build(skill, ctx.params)
        # The blackboard is process-global in py_trees; a session starts from a clean one.
        py_trees.blackboard.Blackboard.clear()
        tree = py_trees.trees.BehaviourTree(root)
        tree.setup(context=ctx)
        ticks = 0
        status = "completed"
        message = ""
        # [view hook, issue 13] live tree status (evidence/<sid>/tree.json), throttled by the observer.
        observe_tree = getattr(ctx, "tree_observer", None)
        ctx.actuation_starts()  # built and set up: the first tick follows
        try:
            while True:
                if ctx.cancel.is_set():
                    status, message = "cancelled", ctx.cancel.reason or "cancel requested"
                    break
                if time.monotonic() > deadline:
                    status, message = "timed_out", "execution timeout exceeded"
                    break
                tree.tick()
                ticks += 1
                if heartbeat is not None:
                    heartbeat()
                if observe_tree is not None:
                    observe_tree(root)
                if root.status == py_trees.common.Status.SUCCESS:
                    break
                if root.status == py_trees.common.Status.FAILURE:
                    status = "failed"
                    break
        finally:
            if observe_tree is not None:
                observe_tree(root, final=True)
            if root.status == py_trees.common.Status.RUNNING:
                root.stop(py_trees.common.Status.INVALID)
            tree.shutdown()
        failure = ctx.failure or {}
        if status == "failed":
            message = failure.get("message", "tree failed")
        code = failure.get("code") if status == "failed" else {"timed_out": "timeout.execution", "cancelled": ctx.cancel.code}.get(status)
        ctx.trace.record("runtime_end", status=status, ticks=ticks, message=message)
        return RunOutcome(status=status, error_code=code, failed_primitive=failure.get("primitive") if status == "failed" else None,
                          message=message, ticks=ticks)
