"""Recipes of a game, earned from evidence: LESSONS.md entries that a later session verifies.

The agent starts without Crafter's recipes. Every ``make`` attempt a game session made
is a ``game_make`` record in its trace (item, ``ok``: the inventory gained the item,
the materials of the player's 3 x 3 neighbourhood, the inventory before and after).
From those records, and nothing else:

1. a failed attempt (inventory unchanged) is evidence: a *candidate* lesson
   ``make <item>: failed next to [...] with {...}`` (no recipe yet, nothing to apply);
2. a successful attempt yields a *hypothesis*, still a candidate: the stations the
   recipe needs are the fewest materials around the success that explain every failure
   of the session that had the items (:func:`hypothesis`), and the items it uses are
   the inventory's decrease;
3. the ContextBuilder hands the hypothesis to the next ``game_make`` session of that
   item (parameter ``near``; the session's context records it); when that session's
   planned attempt succeeds, the candidate becomes a *verified* lesson, ``verified_by``
   that session. A success without one of the stations a recipe names refutes it (it
   asks for too much) and the smaller set becomes the hypothesis; a session that cannot
   follow a recipe searches instead (the skill's own fallback). From then on the generic lesson accounting
   (:meth:`~phyagentos.agent.memory.lessons.LessonBook.resolve`) counts confirmations and
   refutations; a planned attempt that fails refutes the hypothesis.

Lesson ids are ``R`` + a hash of (item, stations), so the same recipe learned in two
worlds is one lesson. The scope is ``{embodiment, skill: game_make, object_class:
item:<item>}`` (the game conditions of :func:`~phyagentos.agent.memory.conditions.session_conditions`).
"""

from __future__ import annotations

import hashlib
import logging
from itertools import combinations
from typing import Any, Iterable, Mapping, Sequence

from phyagentos.protocol import Lesson, LessonsDoc, SessionRecord, Verdict, Workspace
from phyagentos.protocol.lifecycle import utc_now

from .conditions import canonical

__all__ = ["RecipeBook", "recipe_id", "failure_id", "hypothesis", "GROUND"]

logger = logging.getLogger(__name__)

#: Materials a player walks on: background, not stations (Crafter's ``walkable``).
GROUND = frozenset({"grass", "sand", "path"})
_MAX_REFS = 12


def recipe_id(item: str, near: Iterable[str]) -> str:
    """Stable id of the recipe hypothesis "``item`` needs ``near`` around the player"."""
    return "R" + hashlib.sha1(canonical(["recipe", item, sorted(near)]).encode()).hexdigest()[:10]


def failure_id(item: str) -> str:
    """Id of the candidate that collects the failed attempts of ``item`` before any success."""
    return "R" + hashlib.sha1(canonical(["recipe-unknown", item]).encode()).hexdigest()[:10]


def _keep(items: Iterable[str], *new: str) -> list[str]:
    return list(dict.fromkeys([*items, *new]))[-_MAX_REFS:]


def hypothesis(attempts: Sequence[Mapping[str, Any]]) -> tuple[list[str], dict[str, int]] | None:
    """``(stations, uses)`` from one item's ``game_make`` records, or ``None`` without a success.

    Uses: the inventory's decrease in the first success. Stations: the smallest sets of
    non-ground materials around every success that each informative failure (one whose
    inventory held what the success used) lacked at least one of (a minimum hitting set;
    ties are joined, erring toward asking for too much); without informative failures,
    every non-ground material around every success.
    """
    wins = [a for a in attempts if a.get("ok")]
    if not wins:
        return None
    before, after = wins[0].get("inventory_before") or {}, wins[0].get("inventory_after") or {}
    uses = {k: int(before[k]) - int(after.get(k, 0)) for k in before if int(after.get(k, 0)) < int(before[k])}
    common = sorted(set.intersection(*(set(a.get("nearby") or ()) for a in wins)) - GROUND)
    informative = [set(a.get("nearby") or ()) for a in attempts if not a.get("ok")
                   and all(int((a.get("inventory_before") or {}).get(k, 0)) >= n for k, n in uses.items())]
    if not informative:
        return common, uses
    for size in range(1, len(common) + 1):
        hits = [set(c) for c in combinations(common, size) if all(not set(c) <= f for f in informative)]
        if hits:
            return sorted(set().union(*hits)), uses
    return common, uses


class RecipeBook:
    """Learns and serves make-recipes in LESSONS.md of ``workspace`` (module doc)."""

    def __init__(self, workspace: Workspace, *, embodiment: str = "crafter"):
        self.workspace = workspace
        self.embodiment = embodiment

    def _scope(self, item: str) -> dict[str, Any]:
        return {"embodiment": self.embodiment, "skill": "game_make", "object_class": f"item:{item}",
                "risk_factors": []}

    # -- reading -----------------------------------------------------------
    def best(self, item: str) -> tuple[Lesson, bool] | None:
        """The recipe to apply for ``item``: ``(lesson, verified)``. A verified recipe
        confirmed more often than refuted wins; else the candidate hypothesis with the
        fewest refutations (a candidate is applied so that a session can test it)."""
        doc: LessonsDoc = self.workspace.read("LESSONS").data
        scope = self._scope(item)
        good = [l for l in doc.lessons if l.scope == scope and l.revision.get("near") and l.verified
                and l.confirmations > l.refutations]
        if good:
            return max(good, key=lambda l: (l.confirmations - l.refutations, l.updated_at or "")), True
        cands = [c for c in doc.candidates if c.scope == scope and c.revision.get("near")]
        if cands:
            return min(cands, key=lambda c: (c.refutations, -(c.confirmations))), False
        return None

    # -- writing -----------------------------------------------------------
    def learn(self, session: SessionRecord, verdict: Verdict, trace: Sequence[Mapping[str, Any]],
              evidence: Sequence[str] = ()) -> list[str]:
        """Fold ``session``'s ``game_make`` records into LESSONS.md; returns the ids touched."""
        by_item: dict[str, list[Mapping[str, Any]]] = {}
        for rec in trace:
            if rec.get("kind") == "game_make":
                by_item.setdefault(str(rec["item"]), []).append(rec)
        if not by_item:
            return []
        sid = session.session_id
        applied = {i.id for i in (session.context.items if session.context else ()) if i.kind == "lesson" and i.applied}
        now = utc_now()
        touched: list[str] = []
        refs = list(evidence)

        def apply(doc: LessonsDoc) -> None:
            for item, attempts in by_item.items():
                scope = self._scope(item)
                found = hypothesis(attempts)
                planned = [a for a in attempts if a.get("recipe_known")]
                if found is None:
                    fid = failure_id(item)
                    cand = next((c for c in doc.candidates if c.id == fid), None)
                    last = attempts[-1]
                    text = (f"make {item} failed {len(attempts)}x; last next to {last.get('nearby')} with "
                            f"{ {k: v for k, v in (last.get('inventory_before') or {}).items() if v} }: "
                            f"a station or an item is missing")
                    if cand is None:
                        cand = Lesson(id=fid, objective=f"make {item}", evidence=[], cause="recipe.unknown",
                                      correction=text, scope=scope, strategy="recipe", revision={})
                        doc.candidates.append(cand)
                    cand.correction = text
                    cand.provenance = _keep(cand.provenance, sid)
                    cand.evidence = _keep(cand.evidence, *refs)
                    cand.refutations += 1
                    cand.refuted_by = _keep(cand.refuted_by, sid)
                    cand.updated_at = now
                    touched.append(fid)
                    # A planned attempt that failed refutes the hypothesis it applied.
                    for c in doc.candidates:
                        if c.id in applied and c.scope == scope and planned:
                            c.refutations += 1
                            c.refuted_by = _keep(c.refuted_by, sid)
                            c.updated_at = now
                            touched.append(c.id)
                    continue
                stations, uses = found
                wins = [set(a.get("nearby") or ()) for a in attempts if a.get("ok")]
                planned_failed = any(a.get("recipe_known") and not a.get("ok") for a in attempts)
                for c in [*doc.candidates, *doc.lessons]:
                    near = set(c.revision.get("near") or ())
                    if c.scope != scope or not near:
                        continue
                    if any(not near <= w for w in wins) or (planned_failed and c.id in applied):
                        # a success without some station it names: the recipe asks for too much
                        c.refutations += 1
                        c.refuted_by = _keep(c.refuted_by, sid)
                        c.updated_at = now
                        touched.append(c.id)
                    elif c in doc.candidates and near & set(stations) and not near >= set(stations):
                        stations = sorted(near & set(stations))  # both explain the successes: the smaller
                rid = recipe_id(item, stations)
                text = (f"a {item} needs {' and '.join(stations) or 'nothing'} next to the player and uses "
                        f"{', '.join(f'{n} {k}' for k, n in sorted(uses.items())) or 'nothing'}")
                lesson = next((l for l in doc.lessons if l.id == rid), None)
                cand = next((c for c in doc.candidates if c.id == rid), None)
                confirmed_plan = rid in applied and any(a.get("ok") and a.get("recipe_known") for a in attempts)
                fid = failure_id(item)
                failed = next((c for c in doc.candidates if c.id == fid), None)
                if lesson is None and confirmed_plan:
                    base = cand or Lesson(id=rid, objective=f"make {item}", evidence=[], cause="recipe.learned",
                                          correction=text, scope=scope, strategy="recipe",
                                          revision={"near": stations})
                    lesson = base.model_copy(deep=True)
                    lesson.verified = True
                    lesson.confirmations = 1
                    lesson.verified_by = [sid]
                    lesson.evidence = _keep(lesson.evidence, *refs)
                    lesson.updated_at = now
                    doc.lessons.append(lesson)
                    doc.candidates = [c for c in doc.candidates if c.id != rid]
                    logger.info("recipe %s verified by %s: %s", rid, sid, text)
                elif lesson is None:
                    if cand is None:
                        cand = Lesson(id=rid, objective=f"make {item}", evidence=[], cause="recipe.learned",
                                      correction=text, scope=scope, strategy="recipe", revision={"near": stations})
                        doc.candidates.append(cand)
                    cand.provenance = _keep(cand.provenance, sid)
                    cand.evidence = _keep(cand.evidence, *refs)
                    cand.updated_at = now
                    if failed is not None:  # the failures before this success are part of its evidence
                        cand.provenance = _keep(failed.provenance, *cand.provenance)
                        cand.evidence = _keep(failed.evidence, *cand.evidence)
                        doc.candidates = [c for c in doc.candidates if c.id != fid]
                else:
                    lesson.evidence = _keep(lesson.evidence, *refs)  # counts: LessonBook.resolve
                touched.append(rid)

        self.workspace.update("LESSONS", apply)
        return touched
