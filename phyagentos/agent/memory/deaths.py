"""Deaths in a game, diagnosed from the trace, become survival lessons.

A game session's trace records every loss of health (``game_damage``: the creatures
next to the player, daylight, whether it slept, the vitals, what it stood on) and the
death itself (``game_death``). :func:`diagnose_death` reads the last of them:

============================  ==========================================================
cause                         evidence (last damage before death)
============================  ==========================================================
``death.lava``                it stood on lava (Crafter kills at once)
``death.zombie_asleep``       a zombie next to it while it slept (7 damage in Crafter)
``death.zombie``              a zombie next to it (``_night`` appended when daylight < 0.5)
``death.skeleton``            a skeleton or an arrow next to it, or an arrow (skeleton)
                              within 2 cells just before a loss of 2 or more
``death.thirst``              drink at 0
``death.starvation``          food at 0
``death.exhaustion``          energy at 0
``death.unknown``             none of the above
============================  ==========================================================

Each cause maps to a correction of the survival reflex's thresholds (skill parameters
of every game skill): thirst raises ``drink_below``, starvation ``food_below``,
exhaustion and zombies in the sleep ``energy_below`` (sleep earlier, in daylight and in
shelter), zombies at night also ``health_below`` (retreat into a shelter to heal sooner),
zombies by day ``health_below``, ``drink_below`` and ``food_below`` (vitals kept high keep
health regenerating). A death makes a *candidate* (scope: the game's embodiment); the
ContextBuilder applies it to later game sessions so they test it; a later session that
applied it, in which the matching reflex fired at a level the default threshold would
have let pass (the correction changed what the player did), and which did not end in a
death of that cause, verifies it (``verified_by``); dying of the same cause again refutes it. Lava deaths carry no
parameter (the planner already never steps on or next to remembered lava): they are
recorded for the report.
"""

from __future__ import annotations

import hashlib
import logging
from typing import Any, Mapping, Sequence

from phyagentos.protocol import Lesson, LessonsDoc, SessionRecord, Workspace
from phyagentos.protocol.lifecycle import utc_now

from .conditions import canonical

__all__ = ["diagnose_death", "DeathBook", "DEATH_CAUSES", "correction_for", "correction_acted"]

logger = logging.getLogger(__name__)

DEATH_CAUSES = ("death.lava", "death.zombie_asleep", "death.zombie", "death.zombie_night", "death.skeleton",
                "death.thirst", "death.starvation", "death.exhaustion", "death.unknown")
#: Survival reflex defaults of the game skills (trees/game_*.yaml), vital units 0..9.
_DEFAULTS = {"drink_below": 4, "food_below": 4, "energy_below": 3, "health_below": 5}
#: threshold -> (the reflex mode it triggers, the vital it compares)
_REFLEX_MODE = {"drink_below": ("drink", "drink"), "food_below": ("eat", "food"), "energy_below": ("rest", "energy"),
                "health_below": ("retreat", "health")}
_MAX_REFS = 12


def diagnose_death(trace: Sequence[Mapping[str, Any]]) -> tuple[str, dict[str, Any]] | None:
    """``(cause, facts)`` of the death recorded in ``trace``, or ``None`` if it has none."""
    death = next((r for r in reversed(trace) if r.get("kind") == "game_death"), None)
    if death is None:
        return None
    damage = next((r for r in reversed(trace) if r.get("kind") == "game_damage"), None) or {}
    adjacent = set(damage.get("adjacent") or death.get("adjacent") or ())
    facts = {"step": death.get("step"), "adjacent": sorted(adjacent), "daylight": damage.get("daylight"),
             "vitals": {k: death.get(k) for k in ("food", "drink", "energy")}, "sleeping": damage.get("sleeping")}
    if damage.get("standing_on") == "lava":
        return "death.lava", facts
    if "zombie" in adjacent:
        if damage.get("sleeping"):
            return "death.zombie_asleep", facts
        night = damage.get("daylight") is not None and float(damage["daylight"]) < 0.5
        return ("death.zombie_night" if night else "death.zombie"), facts
    if adjacent & {"skeleton", "arrow"}:
        return "death.skeleton", facts
    if set(damage.get("close_before") or ()) & {"skeleton", "arrow"} and int(damage.get("lost") or 0) >= 2:
        # an arrow hits and vanishes in the same step: seen within 2 cells just before a
        # loss of 2 or more (a vital at 0 costs 1), with no zombie next to the player
        return "death.skeleton", facts
    for vital, cause in (("drink", "death.thirst"), ("food", "death.starvation"), ("energy", "death.exhaustion")):
        if death.get(vital) == 0:
            return cause, facts
    return "death.unknown", facts


def correction_for(cause: str, current: Mapping[str, Any]) -> dict[str, int]:
    """Survival thresholds to raise for ``cause``: each to its skill default + 2.

    ``current`` (the dying session's parameters) is not the base: raising from it made
    the first learning runs ratchet (a death with a corrected threshold raised it again,
    up to food_below 8, and a player that eats whenever it is not full wanders off its
    tasks). One cause gives one fixed correction, so repeated deaths of that cause count
    as evidence about the same lesson instead of minting a stronger one."""
    del current
    keys = {"death.thirst": ("drink_below",), "death.starvation": ("food_below",),
            "death.exhaustion": ("energy_below",), "death.zombie_asleep": ("energy_below",),
            "death.zombie_night": ("energy_below", "health_below"),
            "death.zombie": ("health_below", "drink_below", "food_below")}.get(cause, ())
    return {k: _DEFAULTS[k] + 2 for k in keys}


def correction_acted(revision: Mapping[str, Any], trace: Sequence[Mapping[str, Any]]) -> bool:
    """True when a corrected threshold of ``revision`` fired its reflex at a level the
    default would have let pass (``default <= vital < corrected`` in a ``game_reflex``
    record of ``trace``): the lesson changed what the player did, so surviving counts
    for it. A reflex that fired below the default anyway is no evidence for the lesson."""
    reflexes = [r for r in trace if r.get("kind") == "game_reflex"]
    for key, level in revision.items():
        mode, vital = _REFLEX_MODE[key]
        if any(r.get("mode") == mode and r.get(vital) is not None
               and _DEFAULTS[key] <= int(r[vital]) < int(level) for r in reflexes):
            return True
    return False


def _lid(cause: str, revision: Mapping[str, Any]) -> str:
    return "D" + hashlib.sha1(canonical(["death", cause, revision]).encode()).hexdigest()[:10]


def _keep(items, *new):
    return list(dict.fromkeys([*items, *new]))[-_MAX_REFS:]


class DeathBook:
    """Death lessons in LESSONS.md of ``workspace`` (module doc)."""

    def __init__(self, workspace: Workspace, *, embodiment: str = "crafter"):
        self.workspace = workspace
        self.scope = {"embodiment": embodiment, "skill": "game_*", "object_class": None, "risk_factors": []}

    def applicable(self) -> list[tuple[Lesson, bool]]:
        """Survival corrections to apply to a new game session, ``(lesson, verified)``:
        verified lessons confirmed more often than refuted, then candidates never refuted."""
        doc: LessonsDoc = self.workspace.read("LESSONS").data
        out = [(l, True) for l in doc.lessons if l.scope == self.scope and l.revision and l.confirmations > l.refutations]
        out += [(c, False) for c in doc.candidates if c.scope == self.scope and c.revision and c.refutations == 0]
        return out

    def learn(self, session: SessionRecord, trace: Sequence[Mapping[str, Any]], evidence: Sequence[str] = ()) -> list[str]:
        """Record ``session``'s death (if any) and resolve the survival lessons it applied."""
        found = diagnose_death(trace)
        applied = {i.id for i in (session.context.items if session.context else ()) if i.kind == "lesson" and i.applied}
        if found is None and not applied:
            return []
        sid, now = session.session_id, utc_now()
        touched: list[str] = []

        def apply(doc: LessonsDoc) -> None:
            for item in [*doc.candidates, *doc.lessons]:
                if item.id not in applied or item.scope != self.scope:
                    continue
                if found is not None and found[0] == item.cause:
                    item.refutations += 1
                    item.refuted_by = _keep(item.refuted_by, sid)
                elif correction_acted(item.revision, trace):
                    if item in doc.candidates:
                        doc.candidates = [c for c in doc.candidates if c.id != item.id]
                        item.verified = True
                        doc.lessons.append(item)
                    item.confirmations += 1
                    item.verified_by = _keep(item.verified_by, sid)
                else:
                    continue
                item.updated_at = now
                touched.append(item.id)
            if found is None:
                return
            cause, facts = found
            revision = correction_for(cause, session.parameters)
            lid = _lid(cause, revision)
            existing = next((l for l in [*doc.lessons, *doc.candidates] if l.id == lid), None)
            text = (f"died at step {facts['step']} ({cause[6:].replace('_', ' ')}; next to {facts['adjacent'] or 'nothing'}, "
                    f"vitals {facts['vitals']})")
            fix = ", ".join(f"{k}={v}" for k, v in sorted(revision.items())) or "no parameter (avoid it)"
            if existing is None:
                doc.candidates.append(Lesson(id=lid, objective="survive a Crafter episode", evidence=list(evidence),
                                             cause=cause, correction=f"{text}: set {fix}", scope=dict(self.scope),
                                             provenance=[sid], strategy="survival", revision=revision, updated_at=now))
            else:
                existing.provenance = _keep(existing.provenance, sid)
                existing.evidence = _keep(existing.evidence, *evidence)
                existing.updated_at = now
            touched.append(lid)
            logger.info("session %s: %s -> %s", sid, cause, fix)

        self.workspace.update("LESSONS", apply)
        return touched
