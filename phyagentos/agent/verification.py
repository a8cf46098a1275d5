"""Verification for an :class:`~phyagentos.agent.coordinator.AgentCoordinator`: a session
waiting in ``awaiting_verification`` is judged by the SessionVerifier on its evidence bundle
under a verification lease (a verification whose agent died is taken up again), an
*another view* child is judged as the acting session with the view's terminal snapshot,
the evidence retention policy drops a success's images, and the verdict is consolidated
into memory (lessons confirmed or refuted, knowledge counted, procedures promoted).
Its LOG.md line is owed to the coordinator's step (mixed into the coordinator as
:class:`Verification`)."""

from __future__ import annotations

import logging
import os
import socket
from dataclasses import replace
from typing import TYPE_CHECKING

from phyagentos.errors import VerifierError
from phyagentos.protocol import LogEntry, SessionRecord, is_expired, new_lease
from phyagentos.protocol.evidence_markers import PRUNED_MARKER, images_pending, wait_for_images
from phyagentos.protocol.lifecycle import SessionLifecycle, utc_now

from .declared import declared_scene
from .memory import KnowledgeBase, LessonBook, promote
from .memory.conditions import Conditions
from .memory.deaths import SURVIVAL_KEYS
from .memory.game import is_game_skill, learn_game_session
from .memory.promotion import initial_state_fingerprint
from .model_calls import trace_calls, with_calls
from .recovery import SITUATIONAL
from .verifier import EvidenceBundle, load_evidence

if TYPE_CHECKING:
    from phyagentos.protocol import Workspace

    from .goal_graph import GoalGraph
    from .memory import ContextBuilder, PromotionPolicy
    from .verifier import SessionVerifier

# the coordinator's log, as before it was split into mix-ins
logger = logging.getLogger("phyagentos.agent.coordinator")


# A verification holds a lease like a supervisor's claim, so one whose agent process
# died is taken up again by the next agent instead of staying ``verifying`` forever.
_AGENT_ID = f"agent:{socket.gethostname()}:{os.getpid()}"
_VERIFY_LEASE_S = 60.0
#: lifecycle event of a verdict (from ``verifying``) -> the verdict
_VERDICT_OF_EVENT = {"succeed": "success", "fail": "failure", "replan": "replan"}
_EVENT_OF_VERDICT = {verdict: event for event, verdict in _VERDICT_OF_EVENT.items()}


class Verification:
    """Judging finished sessions, evidence retention and consolidation into memory.

    Mixed into :class:`~phyagentos.agent.coordinator.AgentCoordinator`.
    """

    workspace: Workspace
    graph: GoalGraph
    verifier: SessionVerifier
    context_builder: ContextBuilder
    consolidate: bool
    keep_success_images: bool
    promotion: PromotionPolicy
    _owed_log: list[LogEntry]

    def _verify(self, session_id: str) -> SessionRecord | None:
        """Judge ``session_id``'s latest attempt and persist the verdict; returns the record
        as written (None: another agent got there first). Its LOG.md line is owed to
        :meth:`step`."""
        ws = self.workspace
        with ws.session_lock(session_id):
            rec = ws.load_session(session_id)
            resume = rec.state == "verifying" and is_expired(rec.lease)
            if rec.state != "awaiting_verification" and not resume:
                return None  # another agent got there first
            rec.lease = new_lease(_AGENT_ID, ttl_s=_VERIFY_LEASE_S)
            lifecycle = SessionLifecycle(rec, persist=ws.save_session)
            if resume:
                ws.save_session(rec)
            else:
                lifecycle.fire("verify")
        attempt = rec.attempts[-1]
        evidence_dir = ws.root / attempt.evidence
        if self.keep_success_images:
            wait_for_images(evidence_dir)  # kept either way: the verdict references them
        evidence = self._evidence(evidence_dir)
        history = self.lineage(rec)
        judged, judged_evidence = self._judged(rec, evidence, history)
        verdict = self.verifier.verify(judged, judged_evidence, history=history, lineage_depth=len(history))
        if verdict.verdict == "success" and not self.keep_success_images:
            verdict = verdict.model_copy(update={"evidence": [r for r in verdict.evidence if r not in evidence.images]})
            self._prune_images(evidence)
        elif images_pending(evidence_dir):
            # Images are rendered off the critical path; a verdict other than success
            # keeps them and refers to them, so it is judged again once they exist.
            wait_for_images(evidence_dir)
            evidence = self._evidence(evidence_dir, fresh=True)
            verdict = self.verifier.verify(rec, evidence, history=history)
        attempt.verdict = verdict
        # model calls made for this session during its attempt (agent runtime) and its revision (a model reviser)
        calls_for = getattr(self.verifier.recovery, "calls_for", None)
        revised = [rec.session_id] + ([judged.session_id] if judged.session_id != rec.session_id else [])
        rec.context = with_calls(rec.context, trace_calls(evidence.trace, ref=evidence.refs("trace")[0]
                                                          if evidence.refs("trace") else None)
                                 + ([c for sid in revised for c in calls_for(sid)] if calls_for is not None else []))
        event = _EVENT_OF_VERDICT[verdict.verdict]
        rec.lease = None
        lifecycle.fire(event, reason=verdict.reason[:200])
        self._owed_log.append(LogEntry(at=utc_now(), session_id=rec.session_id, node=rec.node,
                                       event=f"verdict_{verdict.verdict}", state=rec.state, message=verdict.reason))
        logger.info("session %s verdict %s: %s", rec.session_id, verdict.verdict, verdict.reason)
        if self.consolidate:
            self._consolidate(rec, verdict, evidence, history)
        return rec

    def _judged(self, rec: SessionRecord, evidence: EvidenceBundle,
                history: list[SessionRecord]) -> tuple[SessionRecord, EvidenceBundle]:
        """What a verification judges: ``rec`` on its own evidence, or for an *another view*
        child the nearest acting ancestor on its evidence with this view's terminal snapshot."""
        if rec.recovery is None or rec.recovery.skill != "observe":
            return rec, evidence
        acting = next((h for h in reversed(history) if h.skill != "observe" and h.attempts
                       and h.attempts[-1].evidence), None)
        if acting is None:
            return rec, evidence
        try:
            base = load_evidence(self.workspace.root / acting.attempts[-1].evidence)
        except VerifierError as exc:
            logger.warning("acting session %s evidence unreadable: %s", acting.session_id, exc)
            return rec, evidence
        files = {**base.files, "terminal": f"../{evidence.directory.name}/{evidence.files.get('terminal', '')}"}
        merged = replace(base, terminal=evidence.terminal, files=files)
        return acting, merged

    def _prune_images(self, evidence: EvidenceBundle) -> None:
        # Retention: a success's verdict, snapshots and trace stay; its RGB images go
        # (the marker first: images the runner writes later are then deleted by it).
        (evidence.directory / PRUNED_MARKER).touch()
        for ref in evidence.images:
            (self.workspace.root / ref).unlink(missing_ok=True)

    def _consolidate(self, rec: SessionRecord, verdict, evidence: EvidenceBundle,
                     history: list[SessionRecord]) -> None:
        """Verified outcomes only: lessons are confirmed or refuted, knowledge counted, procedures promoted."""
        conditions = self._conditions(rec)
        LessonBook(self.workspace).resolve(rec, verdict, conditions, history=history)
        info = self.context_builder.skills.get(rec.skill)
        # survival thresholds are the reflex's, owned by their trials (memory/deaths.py): not a
        # strategy of this skill, so never counted in its knowledge nor promoted with it
        strategy = {k: v for k, v in rec.parameters.items()
                    if info is not None and k in info.optional and k not in SITUATIONAL
                    and not (is_game_skill(rec.skill) and k in SURVIVAL_KEYS)}
        KnowledgeBase(self.workspace).record(
            rec, verdict, conditions, strategy=strategy,
            initial_state=initial_state_fingerprint(evidence.initial, conditions.object))
        learn_game_session(self.workspace, rec, verdict, evidence.trace, evidence.refs("trace"))  # no-op off games
        if verdict.verdict == "success":
            promote(self.workspace, self.promotion)

    def _conditions(self, rec: SessionRecord) -> Conditions:
        if rec.context is not None and rec.context.conditions:
            return Conditions.from_dict(rec.context.conditions)
        return self.context_builder.conditions(goal=f"{self.graph.name}/{rec.node}", skill=rec.skill,
                                               target=rec.target, parameters=rec.parameters,
                                               scene=declared_scene(rec.scene))

