"""Session Compiler: goal-graph nodes become pending sessions in the workspace.

A session is the Agent's contract with the Runtime: goal node, skill and runtime,
target, parameters, acceptance criteria, limits, scene and seed. It is written only
through :meth:`Workspace.submit_session`, the one validated submit path.
"""

from __future__ import annotations

import logging
import secrets
from datetime import datetime, timezone
from typing import Any

from phyagentos.errors import SessionExistsError, VerifierError
from phyagentos.protocol import Limits, Revision, SessionContext, SessionRecord, Workspace
from phyagentos.protocol.lifecycle import utc_now

from .criteria import parse_criteria
from .goal_graph import GoalGraph, GoalNode
from .model_calls import with_calls
from .recovery import RECOVERY_VARIANTS_PARAM, check_recovery_variants

__all__ = ["SessionCompiler", "new_run_id"]

logger = logging.getLogger(__name__)


def new_run_id() -> str:
    """A sortable, unique run id such as ``r20261121T152233-9f3a``."""
    return "r" + datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S") + "-" + secrets.token_hex(2)


class SessionCompiler:
    """Compiles goal-graph nodes of one run into sessions.

    Args:
        workspace: the protocol workspace.
        graph: the validated goal graph.
        run_id: the run the sessions belong to.
        seed: base seed; node ``i`` gets ``seed + i`` so episodes are reproducible.
        evaluation: benchmark evaluation configuration copied into every session
            (``None`` outside a benchmark).
    """

    def __init__(self, workspace: Workspace, graph: GoalGraph, run_id: str, *, seed: int | None = 0,
                 evaluation: dict[str, Any] | None = None):
        self.workspace = workspace
        self.graph = graph
        self.run_id = run_id
        self.seed = seed
        self.evaluation = evaluation

    def compile_node(self, node: GoalNode, *, parent: SessionRecord | None = None,
                     parameters: dict[str, Any] | None = None, limits: dict[str, float] | None = None,
                     context: SessionContext | None = None, recovery: Revision | None = None,
                     skill: str | None = None, target: str | None = None,
                     runtime: str | None = None) -> SessionRecord:
        """Build and submit the session for ``node`` (a child of ``parent`` on replan).

        Args:
            parameters: skill parameters (default: the node's).
            limits: limit values over the node's (a revision may lengthen a deadline).
            context: what the ContextBuilder injected (recorded in the session).
            recovery: the revision a replanned child runs with.
            skill: run this skill instead of the node's (``observe`` for another view).
            target: run on this target instead of the node's (a re-target revision).
            runtime: run with this SkillRuntime instead of the node's (a revision that
                switches to a skill of another runtime: a builtin re-grasp of a policy
                node, another view of it).

        Raises:
            VerifierError: the node's acceptance criteria do not parse, or its
                ``recovery_variants`` name no policy recovery variants (checked here so a
                bad criterion never reaches the runtime, nor a bad ladder its verdict).
            ProtocolError: the submit path refused the record. The id of a session this
                compiler already submitted (a stale listing of the run made its node look
                ready) is not an error: that session is returned, nothing is written.
        """
        parse_criteria(node.accept, where=f"{self.graph.path}:{node.line} accept")
        variants = (parameters if parameters is not None else node.params).get(RECOVERY_VARIANTS_PARAM)
        if variants is not None:  # read by the policy ladder after a failed verdict: refused now, not then
            try:
                check_recovery_variants(variants)
            except ValueError as exc:
                raise VerifierError(f"{self.graph.path}:{node.line} params.{RECOVERY_VARIANTS_PARAM}: {exc}") from None
        if recovery is not None and context is not None and context.model_calls:
            # a child inherits its parent's context, but of the model calls only the plan's: the
            # parent's own attempt and revision calls stay the parent's
            context = context.model_copy(update={"model_calls": [c for c in context.model_calls
                                                                 if c.role == "planner"]})
        if recovery is not None:  # ... and it keeps the calls behind its revision
            context = with_calls(context, recovery.model_calls)
        index = self.graph.node_ids.index(node.id)
        generation = 1 if parent is None else int(parent.session_id.rsplit("-", 1)[1]) + 1
        now = utc_now()
        record = SessionRecord(
            session_id=f"{self.run_id}-{node.id}-{generation}",
            run_id=self.run_id,
            goal_graph=str(self.graph.path) if self.graph.path else None,
            node=node.id,
            parent_session_id=parent.session_id if parent else None,
            depends_on=list(node.depends_on),
            skill=skill or node.skill,
            skill_runtime=runtime or node.runtime,
            target=target or node.target,
            parameters=dict(parameters if parameters is not None else node.params),
            accept=node.accept,
            limits=Limits(**{**node.limits, **(limits or {})}),
            scene=self.graph.scene,
            seed=None if self.seed is None else self.seed + index,
            evaluation=dict(self.evaluation) if self.evaluation is not None else None,
            context=context,
            recovery=recovery,
            state="pending",
            created_at=now,
            updated_at=now,
        )
        try:
            self.workspace.submit_session(record)
        except SessionExistsError:
            # Session ids are derived (run, node, generation): the id being taken means this
            # node's session was submitted already and the listing that made it look ready
            # missed it. Submitting is idempotent; the existing session is the node's.
            existing = self.workspace.load_session(record.session_id)
            if (existing.run_id, existing.node, existing.parent_session_id) != (
                    record.run_id, record.node, record.parent_session_id):
                raise
            logger.warning("session %s was submitted already (a listing of run %s missed it); not submitted "
                           "again", record.session_id, self.run_id)
            return existing
        logger.info("submitted session %s (node %s, skill %s)", record.session_id, node.id, record.skill)
        return record
