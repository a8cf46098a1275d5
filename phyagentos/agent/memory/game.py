"""Game memory, wired into the ContextBuilder and the Agent's consolidation.

- :func:`game_context_items`: what memory gives a new game session: the recipe of the
  item a ``game_make`` session makes (:class:`~.recipes.RecipeBook`; parameter ``near``;
  a candidate recipe is applied so that the session tests it) and the survival
  corrections learned from deaths (:class:`~.deaths.DeathBook`; ``drink_below``,
  ``food_below``, ``energy_below``, ``health_below``: verified ones, and while memory
  learns the open candidates in the run's trial arm), each as a ContextItem with its
  provenance; the summary says which.
- :func:`learn_game_session`: after a game session's verdict, fold its trace into
  LESSONS.md (recipes, deaths) and KNOWLEDGE.md (verified recipes with their counts;
  where each resource was first seen: the materials around it, counted over worlds).

Everything here reads the evidence bundle's trace and the protocol documents only.
"""

from __future__ import annotations

import hashlib
from collections import Counter
from typing import Any, Mapping, Sequence

from phyagentos.protocol import ContextItem, KnowledgeEntry, SessionRecord, Verdict, Workspace
from phyagentos.protocol.lifecycle import utc_now

from .deaths import DeathBook
from .recipes import RecipeBook

__all__ = ["is_game_skill", "game_context_items", "learn_game_session"]

_EMBODIMENT = "crafter"


def is_game_skill(skill: str) -> bool:
    """Game skills are named ``game_*`` (skills/game_*.yaml)."""
    return skill.startswith("game_")


def game_context_items(workspace: Workspace, *, skill: str, parameters: Mapping[str, Any],
                       run_id: str | None = None) -> list[tuple[ContextItem, dict[str, Any]]]:
    """``(item, parameter values it proposes)`` for a new game session (empty otherwise).

    ``run_id``: the run while memory learns (open survival candidates are then applied
    or held back by the run's trial arm, :meth:`~.deaths.DeathBook.applicable`); ``None``
    in a frozen measurement (only verified survival lessons apply)."""
    if not is_game_skill(skill):
        return []
    out: list[tuple[ContextItem, dict[str, Any]]] = []
    if skill == "game_make" and isinstance(parameters.get("item"), str):
        best = RecipeBook(workspace, embodiment=_EMBODIMENT).best(parameters["item"])
        if best is not None:
            lesson, verified = best
            tag = f"verified {lesson.confirmations}x" if verified else "candidate, tested by this session"
            out.append((ContextItem(kind="lesson", id=lesson.id, summary=f"recipe: {lesson.correction} ({tag})",
                                    provenance=list(lesson.verified_by or lesson.provenance)), dict(lesson.revision)))
    for lesson, role in DeathBook(workspace, embodiment=_EMBODIMENT).applicable(run_id=run_id):
        t = lesson.trial
        counts = "" if t is None else (f"; trial: {t.deaths_with} deaths in {t.steps_with} steps with, "
                                       f"{t.deaths_without} in {t.steps_without} without")
        tag = {"verified": "verified by its trial", "with": "trial arm: applied",
               "without": "trial arm: held back (control)"}[role]
        out.append((ContextItem(kind="lesson", id=lesson.id, summary=f"survival: {lesson.correction} ({tag}{counts})",
                                provenance=list(lesson.verified_by or lesson.provenance)),
                    dict(lesson.revision) if role != "without" else {}))
    return out


def learn_game_session(workspace: Workspace, session: SessionRecord, verdict: Verdict,
                       trace: Sequence[Mapping[str, Any]], evidence: Sequence[str] = ()) -> list[str]:
    """Consolidate one game session (no-op for other skills); returns the ids touched."""
    if not is_game_skill(session.skill):
        return []
    touched = RecipeBook(workspace, embodiment=_EMBODIMENT).learn(session, verdict, trace, evidence)
    touched += DeathBook(workspace, embodiment=_EMBODIMENT).learn(session, trace, evidence)
    _knowledge(workspace, session, trace)
    return touched


def _kid(*parts: str) -> str:
    return "K" + hashlib.sha1("/".join(parts).encode()).hexdigest()[:10]


def _knowledge(workspace: Workspace, session: SessionRecord, trace: Sequence[Mapping[str, Any]]) -> None:
    sightings = [r for r in trace if r.get("kind") == "game_sighting"]
    recipes = [entry for entry in workspace.read("LESSONS").data.lessons
               if entry.strategy == "recipe" and entry.verified and entry.scope.get("embodiment") == _EMBODIMENT]
    if not sightings and not recipes:
        return
    now = utc_now()

    def apply(doc) -> None:
        entries = {e.id: e for e in doc.entries}
        for lesson in recipes:
            kid = _kid("recipe", lesson.id)
            e = entries.get(kid)
            if e is None:
                e = KnowledgeEntry(id=kid, pattern="", conditions={"embodiment": _EMBODIMENT, "kind": "recipe",
                                                                   "item": lesson.scope.get("object_class")})
                doc.entries.append(e)
                entries[kid] = e
            e.pattern = f"recipe: {lesson.correction}"
            e.successes = lesson.confirmations
            e.attempts = lesson.confirmations + lesson.refutations
            e.provenance = list(lesson.verified_by)
            e.updated_at = now
        for rec in sightings:
            name = str(rec.get("name"))
            kid = _kid("resource", name)
            e = entries.get(kid)
            if e is None:
                e = KnowledgeEntry(id=kid, pattern="", conditions={"embodiment": _EMBODIMENT, "kind": "resource",
                                                                   "resource": name, "around": {}, "distance": []})
                doc.entries.append(e)
                entries[kid] = e
            around = Counter(e.conditions.get("around") or {})
            around.update(n for n in rec.get("around") or () if n != name)
            dist = [*list(e.conditions.get("distance") or []), int(rec.get("distance_from_start", 0))][-50:]
            e.conditions = {**e.conditions, "around": dict(around.most_common(8)), "distance": dist}
            e.successes += 1
            e.attempts += 1
            e.provenance = list(dict.fromkeys([*e.provenance, session.session_id]))[-12:]
            top = ", ".join(f"{k} ({n})" for k, n in around.most_common(4))
            e.pattern = (f"{name}: first seen {e.successes}x, median {sorted(dist)[len(dist) // 2]} cells from the start, "
                         f"among {top}")
            e.updated_at = now

    workspace.update("KNOWLEDGE", apply)
