"""LESSONS.md: failure-centred lessons, and the candidates that are not lessons yet.

Life of a correction:

1. a ``replan`` verdict diagnoses a cause and proposes a revision; when the child session
   is compiled, :meth:`LessonBook.propose` records a *candidate* (objective, evidence,
   cause, correction, scope, the parent session as provenance);
2. the child's verdict resolves it (:meth:`LessonBook.resolve`): ``success`` makes it a
   verified lesson (the child in ``verified_by``); anything else counts a refutation and
   it stays a candidate. When a lineage needed several replans, the success also
   verifies, for every earlier failure along it, the *cumulative* correction (all the
   parameters the successful child changed relative to that failed session, the
   strategies joined by ``+``): the single step that did not suffice stays a refuted
   candidate, the combination that did becomes the lesson;
3. later sessions that apply a lesson through the ContextBuilder confirm or refute it
   the same way, so its counts keep tracking whether it works. A lesson whose cause
   belongs to the scene (not in :data:`OBJECT_CAUSES`) is not applied up front: it is held
   in the session's context and becomes the first revision if that cause recurs
   (``proposed_by: memory``); that revision's verdict confirms or refutes it.

Every lesson and candidate records who proposed the correction (``proposed_by``: the rule
ladder ``rules`` or the model reviser ``model``; a cumulative correction joins them), what it
runs instead (``skill`` for a skill switch, ``target`` for a re-target) and whether later
verdicts confirmed it (``verified``, ``confirmations``/``verified_by``,
``refutations``/``refuted_by``).

Duplicates merge: the id is a hash of cause, strategy, revision and scope, so the same
correction learned twice is one lesson with two confirmations. Growth is bounded: at
most :data:`MAX_LESSONS` lessons and :data:`MAX_CANDIDATES` candidates (the least
confirmed, then the oldest, go first) and :data:`MAX_REFS` session ids or evidence paths
per list (the most recent are kept).
"""

from __future__ import annotations

import hashlib
import logging
from typing import Any, Iterable, Sequence

from phyagentos.protocol import Diagnosis, Lesson, LessonsDoc, Revision, SessionRecord, Verdict, Workspace
from phyagentos.protocol.lifecycle import utc_now

from ..recovery import MEMORY, SITUATIONAL
from .conditions import Conditions, canonical, scope_identity
from .similarity import MIN_SIMILARITY, similarity

__all__ = ["LessonBook", "lesson_id", "keep_refs", "count_outcome", "held_correction", "MAX_LESSONS",
           "MAX_CANDIDATES", "MAX_REFS", "OBJECT_CAUSES"]

logger = logging.getLogger(__name__)

MAX_LESSONS = 200
#: Failure causes whose correction follows the object wherever it stands: how it holds in
#: the hand, where the fingers meet it, how it settles when let go. A lesson for one of them
#: is applied up front to a session on a similar object. Every other cause (a collision of
#: the goal or the path, a pose out of reach, an object unseen from one view) belongs to
#: the scene around the object: its lesson is held back and becomes the first revision
#: when that cause recurs (:func:`held_correction`), never a change to a first attempt.
OBJECT_CAUSES = frozenset({"object_slipped", "grasp_missed", "placement_off"})
MAX_CANDIDATES = 100
MAX_REFS = 12


def lesson_id(cause: str, strategy: str, revision: dict[str, Any], scope: dict[str, Any]) -> str:
    """Stable id of a correction: equal cause, strategy, revision and scope identity
    (:func:`~.conditions.scope_identity`) give equal ids."""
    digest = hashlib.sha1(canonical([cause, strategy, revision, scope_identity(scope)]).encode()).hexdigest()[:10]
    return f"L{digest}"


def keep_refs(items: Iterable[str], *new: str) -> list[str]:
    """``items`` then ``new`` without repeats, the newest :data:`MAX_REFS` kept."""
    merged = list(dict.fromkeys([*items, *new]))
    return merged[-MAX_REFS:]


_keep = keep_refs


def count_outcome(lesson: Lesson, session_id: str, *, confirmed: bool, now: str) -> None:
    """Count one confirmation (``verified_by``) or refutation (``refuted_by``) of ``lesson`` by
    session ``session_id``, in place."""
    if confirmed:
        lesson.confirmations += 1
        lesson.verified_by = keep_refs(lesson.verified_by, session_id)
    else:
        lesson.refutations += 1
        lesson.refuted_by = keep_refs(lesson.refuted_by, session_id)
    lesson.updated_at = now


def corrective(revision: Revision) -> dict[str, Any]:
    """The parameters of ``revision`` that make the correction (situational ones, such
    as backing off from where a failed attempt left the hand, are not part of it)."""
    return {k: v for k, v in revision.parameters.items() if k not in SITUATIONAL}


def _correction(revision: Revision) -> str:
    sets = [f"{k}={v}" for k, v in sorted(corrective(revision).items())]
    sets += [f"limits.{k}={v}" for k, v in sorted(revision.limits.items())]
    runs = "".join(f"{what} {value}; " for what, value in (("run skill", revision.skill), ("on target", revision.target))
                   if value)
    return f"{revision.strategy}: {runs}set {', '.join(sets)}"


def held_correction(lesson: Lesson) -> dict[str, Any]:
    """What a session's context holds of a situational lesson (see :data:`OBJECT_CAUSES`):
    ``{cause, strategy, parameters, skill}``; empty for a lesson applied up front."""
    if lesson.cause in OBJECT_CAUSES:
        return {}
    return {"cause": lesson.cause, "strategy": lesson.strategy, "parameters": dict(lesson.revision),
            "skill": lesson.skill}


def _bound(items: list[Lesson], limit: int) -> list[Lesson]:
    if len(items) <= limit:
        return items
    ranked = sorted(items, key=lambda entry: (entry.confirmations - entry.refutations, entry.updated_at or ""), reverse=True)
    keep = {entry.id for entry in ranked[:limit]}
    return [entry for entry in items if entry.id in keep]


def _cumulative(child: SessionRecord, history: Sequence[SessionRecord], scope: dict[str, Any],
                conditions: Conditions, now: str) -> list[Lesson]:
    """Verified lessons for the failures before ``child``'s parent along its lineage."""
    out = []
    chain = [*history]
    for i, failed in enumerate(chain[:-1]):
        verdict = failed.attempts[-1].verdict if failed.attempts else None
        if verdict is None or verdict.diagnosis is None:
            continue
        delta = {k: v for k, v in child.parameters.items()
                 if failed.parameters.get(k) != v and k not in SITUATIONAL}
        strategies = [s.recovery.strategy for s in [*chain[i + 1:], child] if s.recovery is not None]
        if not delta or not strategies:
            continue
        strategy = "+".join(strategies)
        proposers = "+".join(dict.fromkeys(s.recovery.proposed_by for s in [*chain[i + 1:], child]
                                           if s.recovery is not None))
        cause = verdict.diagnosis.cause
        lid = lesson_id(cause, strategy, delta, scope)
        sets = ", ".join(f"{k}={v}" for k, v in sorted(delta.items()))
        out.append(Lesson(
            id=lid, objective=f"{conditions.skill} {conditions.object or ''} ({conditions.goal})".replace("  ", " "),
            evidence=_keep((), *verdict.diagnosis.evidence, *(child.attempts[-1].verdict.evidence
                                                              if child.attempts and child.attempts[-1].verdict else ())),
            cause=cause, correction=f"{strategy}: set {sets}", verified=True, verified_by=[child.session_id],
            scope=scope, provenance=[failed.session_id], strategy=strategy, revision=delta, confirmations=1,
            proposed_by=proposers, skill=child.skill if child.skill != failed.skill else None,
            target=child.target if child.target != failed.target else None, updated_at=now))
    return out


class LessonBook:
    """Reads and writes LESSONS.md of ``workspace`` (every write under the document's lock)."""

    def __init__(self, workspace: Workspace):
        self.workspace = workspace

    # -- reading -----------------------------------------------------------

    def document(self) -> LessonsDoc:
        return self.workspace.read("LESSONS").data

    def retrieve(self, conditions: Conditions) -> list[Lesson]:
        """Verified lessons learned on an object like the session's (similarity at least
        :data:`~.similarity.MIN_SIMILARITY`, :mod:`~.similarity`) and confirmed more often than
        refuted; the most similar first, then the most confirmed and the most specific.
        Lessons decided by a trial (survival corrections) are served by their own book
        (:class:`~.deaths.DeathBook`), not here."""
        return [entry for _, entry in self.retrieve_scored(conditions)]

    def retrieve_scored(self, conditions: Conditions) -> list[tuple[float, Lesson]]:
        """:meth:`retrieve` with each lesson's similarity, ``[(similarity, lesson)]``."""
        found = [(round(similarity(entry.scope, conditions), 3), entry) for entry in self.document().lessons
                 if entry.verified and entry.trial is None  # trials: memory/deaths.py
                 and entry.confirmations > entry.refutations]
        found = [(score, entry) for score, entry in found if score >= MIN_SIMILARITY]
        return sorted(found, key=lambda pair: (pair[0], pair[1].confirmations - pair[1].refutations,
                                               len(pair[1].scope.get("risk_factors") or ()), pair[1].updated_at or ""),
                      reverse=True)

    # -- writing -----------------------------------------------------------

    def propose(self, *, parent: SessionRecord, child: SessionRecord, diagnosis: Diagnosis, revision: Revision,
                conditions: Conditions) -> str:
        """Record the correction ``child`` tries for ``parent``'s failure as a candidate; returns its id."""
        scope = conditions.scope()
        lid = lesson_id(revision.cause, revision.strategy, corrective(revision), scope)
        now = utc_now()

        def apply(doc: LessonsDoc) -> None:
            existing = next((c for c in doc.candidates if c.id == lid), None)
            if existing is None:
                doc.candidates.append(Lesson(
                    id=lid, objective=f"{conditions.skill} {conditions.object or ''} ({conditions.goal})".replace("  ", " "),
                    evidence=_keep((), *diagnosis.evidence), cause=revision.cause, correction=_correction(revision),
                    verified=False, scope=scope, provenance=[parent.session_id], strategy=revision.strategy,
                    revision=corrective(revision), proposed_by=revision.proposed_by, skill=revision.skill,
                    target=revision.target, updated_at=now))
            else:
                existing.provenance = _keep(existing.provenance, parent.session_id)
                existing.evidence = _keep(existing.evidence, *diagnosis.evidence)
                existing.updated_at = now
            doc.candidates = _bound(doc.candidates, MAX_CANDIDATES)

        self.workspace.update("LESSONS", apply)
        logger.info("lesson candidate %s: %s for %s (child %s)", lid, revision.strategy, revision.cause, child.session_id)
        return lid

    def resolve(self, session: SessionRecord, verdict: Verdict, conditions: Conditions, *,
                history: Sequence[SessionRecord] = ()) -> list[str]:
        """Let ``session``'s verdict confirm or refute the corrections it tried.

        A replanned child resolves the candidate it was compiled for (and, on success,
        the cumulative corrections for the earlier failures of its lineage ``history``,
        oldest first); a first attempt resolves the lessons the ContextBuilder applied
        to it. Returns the ids touched.
        """
        success = verdict.verdict == "success"
        now = utc_now()
        sid = session.session_id
        touched: list[str] = []
        scope = conditions.scope()
        recovery = session.recovery
        applied = [] if recovery is not None or session.context is None else \
            [i.id for i in session.context.items if i.kind == "lesson" and i.applied]
        if recovery is None and not applied:
            return touched

        def apply(doc: LessonsDoc) -> None:
            if recovery is not None:
                lid = lesson_id(recovery.cause, recovery.strategy, corrective(recovery), scope)
                candidate = next((c for c in doc.candidates if c.id == lid), None)
                lesson = next((entry for entry in doc.lessons if entry.id == lid), None)
                if success:
                    if lesson is None:
                        base = candidate or Lesson(id=lid, objective=f"{conditions.skill} {conditions.object or ''}",
                                                   evidence=[], cause=recovery.cause, correction=_correction(recovery),
                                                   scope=scope, strategy=recovery.strategy,
                                                   revision=corrective(recovery), proposed_by=recovery.proposed_by,
                                                   skill=recovery.skill, target=recovery.target)
                        lesson = base.model_copy(deep=True)
                        lesson.confirmations = 0
                        doc.lessons.append(lesson)
                    elif candidate is not None:
                        lesson.provenance = _keep(lesson.provenance, *candidate.provenance)
                        lesson.refutations += candidate.refutations
                        lesson.refuted_by = _keep(lesson.refuted_by, *candidate.refuted_by)
                    lesson.verified = True
                    lesson.confirmations += 1
                    lesson.verified_by = _keep(lesson.verified_by, sid)
                    lesson.evidence = _keep(lesson.evidence, *(candidate.evidence if candidate else ()), *verdict.evidence)
                    lesson.updated_at = now
                    doc.candidates = [c for c in doc.candidates if c.id != lid]
                else:
                    if candidate is not None:
                        candidate.refutations += 1
                        candidate.refuted_by = _keep(candidate.refuted_by, sid)
                        candidate.updated_at = now
                    if lesson is not None and recovery.proposed_by == MEMORY:
                        count_outcome(lesson, sid, confirmed=False, now=now)  # a held lesson that did not help
                touched.append(lid)
            if recovery is not None and success:
                for lesson in _cumulative(session, history, scope, conditions, now):
                    existing = next((entry for entry in doc.lessons if entry.id == lesson.id), None)
                    if existing is None:
                        doc.lessons.append(lesson)
                    else:
                        existing.verified = True
                        existing.confirmations += 1
                        existing.verified_by = _keep(existing.verified_by, sid)
                        existing.provenance = _keep(existing.provenance, *lesson.provenance)
                        existing.evidence = _keep(existing.evidence, *lesson.evidence)
                        existing.updated_at = now
                    touched.append(lesson.id)
            for lid in applied:
                lesson = next((entry for entry in doc.lessons if entry.id == lid), None)
                if lesson is None or lesson.trial is not None or lesson.strategy == "recipe":
                    continue  # decided by their own evidence: a trial (deaths.py), planned makes (recipes.py)
                count_outcome(lesson, sid, confirmed=success, now=now)
                touched.append(lid)
            doc.lessons = _bound(doc.lessons, MAX_LESSONS)

        self.workspace.update("LESSONS", apply)
        return touched

