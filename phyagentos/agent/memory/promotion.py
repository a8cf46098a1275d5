"""Promotion: a pattern verified often enough, from varied initial states, becomes a
procedure in SKILL.md (the methodological level of memory).

A KNOWLEDGE.md entry is promoted when, under :class:`PromotionPolicy`:

- it sets strategy parameters (an entry with ``{}`` is the plain skill: nothing to promote);
- it has at least ``min_successes`` verified successes,
- an observed success rate ``successes / attempts`` of at least ``min_success_rate``,
- from at least ``min_initial_states`` distinct initial states (object positions
  rounded to 1 cm, see :func:`initial_state_fingerprint`).

Promotion is idempotent: a promoted procedure's counts are refreshed on every pass, and
a procedure whose entry falls below the success rate is withdrawn. At most
``max_procedures`` are kept (most successful first).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any, Mapping

from phyagentos.protocol import KnowledgeEntry, SkillDoc, SkillProcedure, Workspace
from phyagentos.protocol.lifecycle import utc_now

__all__ = ["PromotionPolicy", "promote", "initial_state_fingerprint"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class PromotionPolicy:
    """Thresholds for promoting a KNOWLEDGE.md entry to SKILL.md (see the module docstring)."""

    min_successes: int = 5
    min_success_rate: float = 0.8
    min_initial_states: int = 3
    max_procedures: int = 64

    def qualifies(self, entry: KnowledgeEntry) -> bool:
        return (bool(entry.parameters) and entry.successes >= self.min_successes
                and entry.successes >= self.min_success_rate * max(entry.attempts, 1)
                and len(entry.initial_states) >= self.min_initial_states)


def initial_state_fingerprint(initial: Mapping[str, Any], obj: str | None) -> str | None:
    """``"x,y"`` (cm) of ``obj`` in an initial snapshot, ``None`` if it is not there; for a
    game, whose snapshot's ``player`` names the world it plays in, ``"world:<seed>"``."""
    for e in initial.get("entities", []):
        if e.get("name") == "player" and (e.get("attributes") or {}).get("world") is not None:
            return f"world:{e['attributes']['world']}"
    for e in initial.get("entities", []) if obj else ():
        if e.get("name") == obj:
            x, y = e["position"][:2]
            return f"{float(x) * 100:.0f},{float(y) * 100:.0f}"
    return None


def _procedure_name(entry: KnowledgeEntry) -> str:
    return f"{entry.conditions.get('skill')}.{entry.id}"


def promote(workspace: Workspace, policy: PromotionPolicy = PromotionPolicy()) -> list[str]:
    """Bring SKILL.md in line with KNOWLEDGE.md under ``policy``; returns the names of
    procedures promoted for the first time."""
    entries = workspace.read("KNOWLEDGE").data.entries
    qualified = {_procedure_name(e): e for e in entries if policy.qualifies(e)}
    now = utc_now()
    new: list[str] = []

    def apply(doc: SkillDoc) -> None:
        kept = []
        for proc in doc.procedures:
            entry = qualified.pop(proc.name, None)
            if entry is None:
                logger.info("procedure %s withdrawn: its knowledge entry no longer qualifies", proc.name)
                continue
            proc.successes, proc.attempts = entry.successes, entry.attempts
            proc.distinct_initial_states = len(entry.initial_states)
            proc.provenance = list(entry.provenance)
            proc.updated_at = now
            kept.append(proc)
        for name, entry in qualified.items():
            kept.append(SkillProcedure(
                name=name, base_skill=str(entry.conditions.get("skill")), description=entry.pattern,
                conditions=dict(entry.conditions), parameters=dict(entry.parameters), knowledge_id=entry.id,
                provenance=list(entry.provenance), successes=entry.successes, attempts=entry.attempts,
                distinct_initial_states=len(entry.initial_states), promoted_at=now, updated_at=now))
            new.append(name)
        kept.sort(key=lambda p: p.successes, reverse=True)
        doc.procedures = kept[:policy.max_procedures]

    before = workspace.read("SKILL").data
    if not qualified and not before.procedures:
        return new  # nothing to write: keep SKILL.md untouched
    workspace.update("SKILL", apply)
    for name in new:
        logger.info("promoted procedure %s to SKILL.md", name)
    return new
