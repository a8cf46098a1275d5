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
   item (parameter ``near``; the session's context records it). A recipe is judged only
   by the attempts made *as planned* with it (``recipe_known``): a planned success
   confirms it (a candidate becomes a *verified* lesson, ``verified_by`` that session)
   and mints no new hypothesis (the plan explains the success; a hypothesis from one
   success and no failure would name every material around it); a planned failure with
   the items the recipe uses in hand refutes it; a session that never tried it as
   planned (it died first, or lacked the items) is no evidence either way, and so is
   its verdict (the generic verdict accounting,
   :meth:`~phyagentos.agent.memory.lessons.LessonBook.resolve`, leaves recipes alone:
   it refuted verified recipes for sessions that died before they could make
   anything). A success the *search* found without one of the stations a recipe names
   refutes that recipe (it asks for too much) and the smaller set becomes the
   hypothesis.

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
from .lessons import count_outcome
from .lessons import keep_refs as _keep

__all__ = ["RecipeBook", "recipe_id", "failure_id", "hypothesis", "GROUND"]

logger = logging.getLogger(__name__)

#: Materials a player walks on: background, not stations (Crafter's ``walkable``).
GROUND = frozenset({"grass", "sand", "path"})


def recipe_id(item: str, near: Iterable[str]) -> str:
    """Stable id of the recipe hypothesis "``item`` needs ``near`` around the player"."""
    return "R" + hashlib.sha1(canonical(["recipe", item, sorted(near)]).encode()).hexdigest()[:10]


def failure_id(item: str) -> str:
    """Id of the candidate that collects the failed attempts of ``item`` before any success."""
    return "R" + hashlib.sha1(canonical(["recipe-unknown", item]).encode()).hexdigest()[:10]


def _holds(attempt: Mapping[str, Any], uses: Mapping[str, int]) -> bool:
    """The inventory before ``attempt`` held every item of ``uses``."""
    inv = attempt.get("inventory_before") or {}
    return all(int(inv.get(k, 0)) >= int(n) for k, n in uses.items())


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
        good = [entry for entry in doc.lessons if entry.scope == scope and entry.revision.get("near") and entry.verified
                and entry.confirmations > entry.refutations]
        if good:
            return max(good, key=lambda entry: (entry.confirmations - entry.refutations, entry.updated_at or "")), True
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

        def count(lesson: Lesson, *, confirm: bool) -> None:
            count_outcome(lesson, sid, confirmed=confirm, now=now)
            lesson.evidence = _keep(lesson.evidence, *refs)
            touched.append(lesson.id)

        def apply(doc: LessonsDoc) -> None:
            for item, attempts in by_item.items():
                scope = self._scope(item)
                # 1. the recipe memory handed over, judged by its planned attempts only: a
                #    planned success confirms it (a candidate becomes a lesson); a planned
                #    failure with the items it uses in hand refutes it; a session that never
                #    tried it as planned (it died, lacked the items) says nothing about it
                planned_ok = any(a.get("ok") and a.get("recipe_known") for a in attempts)
                for lesson in [entry for entry in [*doc.candidates, *doc.lessons]
                               if entry.id in applied and entry.scope == scope and entry.revision.get("near")]:
                    uses = lesson.revision.get("uses") or {}
                    failed_in_hand = any(a.get("recipe_known") and not a.get("ok") and _holds(a, uses) for a in attempts)
                    if planned_ok:
                        if lesson in doc.candidates:
                            doc.candidates = [c for c in doc.candidates if c.id != lesson.id]
                            lesson.verified = True
                            doc.lessons.append(lesson)
                            logger.info("recipe %s verified by %s: %s", lesson.id, sid, lesson.correction)
                        count(lesson, confirm=True)
                    elif failed_in_hand:
                        count(lesson, confirm=False)
                if planned_ok:
                    continue  # the plan explains the success: no new hypothesis from it
                found = hypothesis(attempts)
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
                    count_outcome(cand, sid, confirmed=False, now=now)
                    touched.append(fid)
                    continue
                # 2. a success the search found: a hypothesis (still a candidate)
                stations, uses = found
                wins = [set(a.get("nearby") or ()) for a in attempts if a.get("ok")]
                for c in [*doc.candidates, *doc.lessons]:
                    near = set(c.revision.get("near") or ())
                    if c.scope != scope or not near:
                        continue
                    if any(not near <= w for w in wins):
                        count(c, confirm=False)  # a success without some station it names: it asks for too much
                    elif c in doc.candidates and near & set(stations) and not near >= set(stations):
                        stations = sorted(near & set(stations))  # both explain the successes: the smaller
                rid = recipe_id(item, stations)
                text = (f"a {item} needs {' and '.join(stations) or 'nothing'} next to the player and uses "
                        f"{', '.join(f'{n} {k}' for k, n in sorted(uses.items())) or 'nothing'}")
                lesson = next((entry for entry in doc.lessons if entry.id == rid), None)
                cand = next((c for c in doc.candidates if c.id == rid), None)
                fid = failure_id(item)
                failed = next((c for c in doc.candidates if c.id == fid), None)
                if lesson is None:
                    if cand is None:
                        cand = Lesson(id=rid, objective=f"make {item}", evidence=[], cause="recipe.learned",
                                      correction=text, scope=scope, strategy="recipe",
                                      revision={"near": stations, "uses": uses})
                        doc.candidates.append(cand)
                    cand.provenance = _keep(cand.provenance, sid)
                    cand.evidence = _keep(cand.evidence, *refs)
                    cand.updated_at = now
                    if failed is not None:  # the failures before this success are part of its evidence
                        cand.provenance = _keep(failed.provenance, *cand.provenance)
                        cand.evidence = _keep(failed.evidence, *cand.evidence)
                        doc.candidates = [c for c in doc.candidates if c.id != fid]
                else:
                    lesson.evidence = _keep(lesson.evidence, *refs)  # consistent with it, but not its test
                touched.append(rid)

        self.workspace.update("LESSONS", apply)
        return touched
