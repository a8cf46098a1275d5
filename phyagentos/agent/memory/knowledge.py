"""KNOWLEDGE.md: verified successful patterns, their conditions, provenance and counts.

A *pattern* is a skill run with particular strategy parameters (the skill's optional
parameters as the session set them; ``{}`` is the skill's defaults) under particular
conditions (embodiment, target, skill, object class, risk factors, the object's observable
properties; retrieved by similarity, :mod:`~.similarity`). A success verdict
creates the pattern or adds to it (``successes``, the session in ``provenance``, the
initial state in ``initial_states``); any later verdict of the same pattern counts as an
attempt, so ``successes / attempts`` is its observed success rate from its first
verified success on.

Growth is bounded: one entry per distinct pattern (duplicates merge), at most
:data:`MAX_ENTRIES` entries (the least successful go first), :data:`MAX_REFS` session
ids and :data:`MAX_STATES` initial-state fingerprints per entry.
"""

from __future__ import annotations

import hashlib
from typing import Any, Mapping

from phyagentos.protocol import KnowledgeDoc, KnowledgeEntry, SessionRecord, Verdict, Workspace
from phyagentos.protocol.lifecycle import utc_now

from .conditions import Conditions, canonical, migrate_scope
from .similarity import MIN_SIMILARITY, similarity

__all__ = ["KnowledgeBase", "knowledge_id", "pattern_conditions", "MAX_ENTRIES", "MAX_REFS", "MAX_STATES"]

MAX_ENTRIES = 200
MAX_REFS = 16
MAX_STATES = 32


def pattern_conditions(conditions: Conditions) -> dict[str, Any]:
    """The applicability conditions recorded with a pattern."""
    return {"embodiment": conditions.embodiment, "target": conditions.target, "skill": conditions.skill,
            "object_class": conditions.object_class, "object_properties": dict(conditions.object_properties),
            "risk_factors": list(conditions.risk_factors)}


def _key_conditions(c: Mapping[str, Any]) -> dict[str, Any]:
    c = migrate_scope(c)  # entries written under the older scope scheme are read in the current one
    return {k: c.get(k) for k in ("embodiment", "skill", "object_class", "risk_factors")}


def knowledge_id(conditions: Mapping[str, Any], parameters: Mapping[str, Any]) -> str:
    """Stable id of a pattern (conditions that matter for applicability + parameters)."""
    return "K" + hashlib.sha1(canonical([_key_conditions(conditions), dict(parameters)]).encode()).hexdigest()[:10]


def _describe(skill: str, parameters: Mapping[str, Any], conditions: Mapping[str, Any]) -> str:
    how = ", ".join(f"{k}={v}" for k, v in sorted(parameters.items())) or "default parameters"
    risks = ", ".join(conditions.get("risk_factors") or ()) or "no risk factors"
    return f"{skill} with {how} on {conditions.get('embodiment')} ({conditions.get('object_class')}, {risks})"


class KnowledgeBase:
    """Reads and writes KNOWLEDGE.md of ``workspace`` (every write under the document's lock)."""

    def __init__(self, workspace: Workspace):
        self.workspace = workspace

    def document(self) -> KnowledgeDoc:
        return self.workspace.read("KNOWLEDGE").data

    def retrieve(self, conditions: Conditions) -> list[KnowledgeEntry]:
        """Patterns learned on an object like the session's (similarity at least
        :data:`~.similarity.MIN_SIMILARITY`, :mod:`~.similarity`), best observed success rate
        (Laplace: ``(successes + 1) / (attempts + 2)``) first, then the most similar."""
        scored = [(similarity(e.conditions, conditions), e) for e in self.document().entries]
        found = [(score, e) for score, e in scored if score >= MIN_SIMILARITY]
        found.sort(key=lambda pair: ((pair[1].successes + 1) / (pair[1].attempts + 2), pair[0], pair[1].successes),
                   reverse=True)
        return [e for _, e in found]

    def record(self, session: SessionRecord, verdict: Verdict, conditions: Conditions, *,
               strategy: Mapping[str, Any], initial_state: str | None) -> str | None:
        """Count ``session``'s verdict for the pattern (``strategy`` parameters under
        ``conditions``); returns the entry id, or ``None`` for a failure of a pattern
        never verified."""
        cond = pattern_conditions(conditions)
        kid = knowledge_id(cond, strategy)
        success = verdict.verdict == "success"
        now = utc_now()
        result: list[str | None] = [None]

        def apply(doc: KnowledgeDoc) -> None:
            entry = next((e for e in doc.entries if e.id == kid), None)
            if entry is None:
                if not success:
                    return
                entry = KnowledgeEntry(id=kid, pattern=_describe(session.skill, strategy, cond), conditions=cond,
                                       parameters=dict(strategy))
                doc.entries.append(entry)
            entry.attempts += 1
            if success:
                entry.successes += 1
                entry.provenance = list(dict.fromkeys([*entry.provenance, session.session_id]))[-MAX_REFS:]
                if initial_state and initial_state not in entry.initial_states:
                    entry.initial_states = [*entry.initial_states, initial_state][-MAX_STATES:]
            entry.updated_at = now
            if len(doc.entries) > MAX_ENTRIES:
                ranked = sorted(doc.entries, key=lambda e: (e.successes, e.updated_at or ""), reverse=True)
                keep = {e.id for e in ranked[:MAX_ENTRIES]}
                doc.entries = [e for e in doc.entries if e.id in keep]
            result[0] = kid

        self.workspace.update("KNOWLEDGE", apply)
        return result[0]
