"""Base class of every primitive leaf.

py_trees semantics: ``setup`` receives the session's :class:`SkillContext` once,
``initialise`` runs when the leaf is entered, ``update`` is called every tick and
returns RUNNING / SUCCESS / FAILURE, ``terminate`` runs when it leaves (including
preemption). Subclasses implement :meth:`step` (and optionally ``on_enter`` /
``on_exit``); the base turns motion and target exceptions into FAILURE with an
error code recorded in the context, so a failed IK is an outcome with evidence,
not a crash.
"""

from __future__ import annotations

import logging
from typing import Any

import py_trees
from py_trees.common import Access, Status

from phyagentos.errors import IKError, MotionError, PlanningError, SkillError, TargetError, TimingError

from .context import SkillContext

__all__ = ["Primitive", "PrimitiveFailure", "ERROR_CODES"]

logger = logging.getLogger(__name__)

#: Exception type -> error code in the session's evidence (most specific first).
ERROR_CODES: tuple[tuple[type[Exception], str], ...] = (
    (IKError, "ik.unreachable"),
    (PlanningError, "planning.failed"),
    (TimingError, "timing.failed"),
    (MotionError, "motion.failed"),
    (TargetError, "target.error"),
)


class PrimitiveFailure(Exception):
    """Raised inside :meth:`Primitive.step` to fail the leaf with a specific code."""

    def __init__(self, code: str, message: str):
        self.code = code
        super().__init__(message)


class Primitive(py_trees.behaviour.Behaviour):
    """A registered leaf: one robot capability with declared blackboard I/O.

    Class attributes:
        TOOLS: target operations the primitive invokes (preflight checks them
            against the target and records them in the TargetToolManifest).
    """

    TOOLS: tuple[str, ...] = ()

    def __init__(self, name: str):
        super().__init__(name=name)
        self.ctx: SkillContext | None = None
        self._reads: list[str] = []
        self._writes: list[str] = []
        self._entered: Status | None = None

    # -- blackboard ------------------------------------------------------

    def reads(self, *keys: str) -> None:
        """Declare blackboard keys this leaf reads (call in ``__init__``)."""
        self._reads.extend(keys)

    def writes(self, *keys: str) -> None:
        """Declare blackboard keys this leaf writes (call in ``__init__``)."""
        self._writes.extend(keys)

    def get(self, key: str) -> Any:
        try:
            return self.bb.get(key)
        except KeyError:
            raise PrimitiveFailure("skill.blackboard", f"blackboard key {key!r} was never written (tree order?)") from None

    def set(self, key: str, value: Any) -> None:
        self.bb.set(key, value, overwrite=True)

    # -- py_trees lifecycle ----------------------------------------------

    def setup(self, **kwargs: Any) -> None:
        ctx = kwargs.get("context")
        if not isinstance(ctx, SkillContext):
            raise SkillError(f"primitive {self.name!r} needs setup(context=SkillContext)")
        self.ctx = ctx
        self.bb = self.attach_blackboard_client(name=self.name)
        for key in self._reads:
            self.bb.register_key(key=key, access=Access.READ)
        for key in self._writes:
            self.bb.register_key(key=key, access=Access.WRITE)

    def initialise(self) -> None:
        self._entered = self._guard(self.on_enter)

    def update(self) -> Status:
        if self._entered == Status.FAILURE:
            return Status.FAILURE  # on_enter failed (recorded in the context): never step half set up
        return self._guard(self.step)

    def terminate(self, new_status: Status) -> None:
        self.on_exit(new_status)

    def _guard(self, fn) -> Status:
        assert self.ctx is not None, "setup() was not called"
        try:
            result = fn()
            return Status.SUCCESS if result is None else result
        except PrimitiveFailure as exc:
            return self._fail(exc.code, str(exc))
        except (MotionError, TargetError) as exc:
            code = getattr(exc, "code", None) or next(c for t, c in ERROR_CODES if isinstance(exc, t))
            return self._fail(code, str(exc))

    def _fail(self, code: str, message: str) -> Status:
        self.feedback_message = f"{code}: {message}"
        self.ctx.fail(code, self.name, message)
        logger.info("%s failed: %s: %s", self.name, code, message)
        self._failed = True
        return Status.FAILURE

    # -- to override -----------------------------------------------------

    def on_enter(self) -> Status | None:
        """Called when the leaf is entered; may raise :class:`PrimitiveFailure`."""
        return None

    def step(self) -> Status | None:
        """One tick of work; return RUNNING to be ticked again, SUCCESS (or None) when done."""
        raise NotImplementedError

    def on_exit(self, new_status: Status) -> None:
        """Called when the leaf stops (finished or preempted)."""
