"""Replanning for an :class:`~phyagentos.agent.coordinator.AgentCoordinator`: a session in
``awaiting_replan`` gets an immutable child session with its revision (parameters, skill
and its runtime, limits, another view, a re-target), the correction it tries proposed as a
lesson candidate; a revision that re-opens an upstream node compiles a re-pick of that node
instead, and the node's child once the re-pick succeeded (mixed into the coordinator as
:class:`Replanning`).

A child that switches skill runs on that skill's runtime (``Revision.runtime``, else its
manifest's): a builtin ``pick`` re-grasp of a ``policy`` node runs ``builtin``; a revision
naming the node's own skill again (the policy's continuation after that re-grasp) continues
the parameters of the lineage's nearest session of the node's skill."""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING, Mapping

from phyagentos.protocol import SessionRecord
from phyagentos.protocol.lifecycle import SessionLifecycle

from .memory import LessonBook
from .recovery import POLICY_STRATEGIES
from .skill_catalog import skill_catalog

if TYPE_CHECKING:
    from phyagentos.protocol import Workspace

    from .goal_graph import GoalGraph
    from .session_compiler import SessionCompiler

# the coordinator's log, as before it was split into mix-ins
logger = logging.getLogger("phyagentos.agent.coordinator")


def _descends(session_id: str | None, ancestor: str, parents: Mapping[str, str | None]) -> bool:
    """``session_id`` is ``ancestor`` or one of its descendants along ``parent_session_id``."""
    seen = set()
    while session_id is not None and session_id not in seen:
        if session_id == ancestor:
            return True
        seen.add(session_id)
        session_id = parents.get(session_id)
    return False


class Replanning:
    """Child sessions of replanned sessions, re-picks of re-opened upstream nodes.

    Mixed into :class:`~phyagentos.agent.coordinator.AgentCoordinator`.
    """

    workspace: Workspace
    graph: GoalGraph
    compiler: SessionCompiler
    consolidate: bool

    def _replan(self, session_id: str) -> int:
        ws = self.workspace
        rec = ws.load_session(session_id)
        verdict = rec.attempts[-1].verdict if rec.attempts else None
        revision = verdict.revision if verdict is not None else None
        if revision is not None and revision.reopen:
            return self._reopen(rec, revision)
        history = self.lineage(rec)
        node = self.graph.get_node(rec.node)
        # back to the node's own skill after a switch (the policy's continuation after a builtin
        # re-grasp): the child continues the nearest session that ran the node's skill
        back = revision is not None and revision.skill == node.skill and rec.skill != node.skill
        # an another-view session's child continues the acting session's parameters
        acting = next((h for h in reversed([*history, rec])
                       if (h.skill == node.skill if back else h.skill != "observe")), rec)
        if revision is not None and revision.skill and not back:
            skill, params = revision.skill, dict(revision.parameters)
        else:  # the acting session's skill: the node's, or the one an earlier revision switched to
            skill = acting.skill if acting.skill != node.skill else None
            params = {**acting.parameters, **(revision.parameters if revision else {})}
        limits = {**acting.limits.model_dump(), **(revision.limits if revision else {})}
        # a re-target moves the node (and its later children) to the selector's other target
        target = revision.target if revision is not None and revision.target else \
            (acting.target if acting.target != node.target else None)
        child = self.compiler.compile_node(node, parent=rec, parameters=params, limits=limits, context=acting.context,
                                           recovery=revision, skill=skill, target=target,
                                           runtime=self._child_runtime(skill, revision, acting))
        with ws.session_lock(session_id):
            rec = ws.load_session(session_id)
            rec.child_session_ids.append(child.session_id)
            SessionLifecycle(rec, persist=ws.save_session).fire("replanned", reason=f"child {child.session_id}")
        # another view only looks again (no correction to learn); a skill switch or re-target is one.
        # The policy ladder's variants answer what this episode left undone (a prompt for the steps
        # that remain, a re-grasp of this object): no correction for another episode to learn either
        if self.consolidate and revision is not None and verdict.diagnosis is not None and revision.skill != "observe" \
                and revision.strategy not in POLICY_STRATEGIES:
            LessonBook(ws).propose(parent=acting, child=child, diagnosis=verdict.diagnosis, revision=revision,
                                   conditions=self._conditions(acting))
        return 1

    @staticmethod
    def _child_runtime(skill: str | None, revision, acting: SessionRecord) -> str | None:
        """The SkillRuntime of a child that runs ``skill`` (``None``: the node's skill, and its
        runtime): the revision's ``runtime``, else the acting session's when it continues its
        switched skill, else the runtime the skill's manifest names (an ``observe`` child of a
        ``policy`` node runs ``builtin``: preflight refuses a skill on another runtime than its own)."""
        if skill is None:
            return None
        if revision is not None and revision.runtime:
            return revision.runtime
        if skill == acting.skill:
            return acting.skill_runtime
        info = skill_catalog().get(skill)
        return info.runtime if info is not None else None

    def _reopen(self, rec: SessionRecord, revision) -> int:
        """Re-open ``revision.reopen`` upstream of ``rec`` (a re-pick); ``rec``'s node runs
        again once it succeeded (:meth:`_resume_after_reopen`)."""
        ws = self.workspace
        upstream = self.latest_by_node().get(revision.reopen)
        node = self.graph.get_node(revision.reopen)
        base = dict(upstream.parameters) if upstream is not None else dict(node.params)
        params = {**base, **revision.parameters}  # e.g. the slip's firmer grip, applied to the re-pick
        repick = self.compiler.compile_node(node, parent=upstream, parameters=params,
                                            context=upstream.context if upstream is not None else None,
                                            recovery=revision, target=upstream.target if upstream is not None else None)
        verdict = rec.attempts[-1].verdict if rec.attempts else None
        if self.consolidate and revision.parameters and upstream is not None and verdict is not None \
                and verdict.diagnosis is not None:
            LessonBook(ws).propose(parent=upstream, child=repick, diagnosis=verdict.diagnosis, revision=revision,
                                   conditions=self._conditions(upstream))
        with ws.session_lock(rec.session_id):
            rec = ws.load_session(rec.session_id)
            rec.child_session_ids.append(repick.session_id)
            SessionLifecycle(rec, persist=ws.save_session).fire(
                "replanned", reason=f"re-opened {revision.reopen} as {repick.session_id}")
        logger.info("session %s: re-opened upstream node %s as %s", rec.session_id, revision.reopen,
                    repick.session_id)
        return 1

    def _resume_after_reopen(self, sessions: list[SessionRecord]) -> int:
        """Compile the child of every node whose re-opened upstream node has succeeded again."""
        actions = 0
        latest = self.latest_by_node(sessions)
        parents = {s.session_id: s.parent_session_id for s in sessions}
        for node_id, (rec, upstream) in self._awaiting_reopen(latest).items():
            up = latest.get(upstream)
            repick = rec.child_session_ids[0] if rec.child_session_ids else None
            # the re-pick itself, or a child the verifier made of it (a re-pick that replanned)
            if up is None or repick is None or up.state != "succeeded" or not _descends(up.session_id, repick, parents):
                continue
            rev = self._revision(rec)
            resume = rev.model_copy(update={"rationale": f"{rev.rationale}; upstream {repick} succeeded"})
            self.compiler.compile_node(self.graph.get_node(node_id), parent=rec, parameters=dict(rec.parameters),
                                       limits=rec.limits.model_dump(), context=rec.context, recovery=resume,
                                       target=rec.target)
            actions += 1
        return actions

