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
health regenerating). A death makes a *candidate* (scope: the game's embodiment).

**A survival correction is decided by a randomised comparison, not by survivors.** A
threshold that sends the player to drink earlier can prevent one death and cause
another (it walks off into the night); a session that applied it and lived says
nothing about that, and the first learning passes, which verified corrections that way,
made the frozen pass 3 to 23 points worse than no memory (docs/crafter.md). So while
memory learns (the AgentCoordinator consolidates), every run is assigned to one arm of
each open candidate's trial by a hash of (run id, lesson id) (:func:`trial_arm`, half
and half, independent across candidates): the ``with`` arm applies the correction, the
``without`` arm holds it back (its sessions record the item with nothing applied). Each
session of an assigned run adds its game steps and its death (any cause) to its arm
(:class:`~phyagentos.protocol.Trial`). The death rates per step of the two arms are
compared with the exact conditional test for two Poisson rates (given n deaths in all,
the with-arm's deaths are Binomial(n, its share of the steps) when the rates are equal;
Przyborowski and Wilenski, Biometrika 31, 1940): once each arm has
:data:`TRIAL_MIN_STEPS` steps and both together :data:`TRIAL_MIN_DEATHS` deaths, a
one-sided p of at most :data:`TRIAL_ALPHA` for fewer deaths *with* the correction
verifies it, and for more deaths refutes it. The test is rerun after every session, so
the real false-positive rate is above the nominal alpha (repeated looks); hence the
small alpha. Verified corrections apply to every later game session; refuted ones to
none; undecided candidates only inside a trial, never in a frozen measurement. Lava
deaths carry no parameter (the planner already never steps on or next to remembered
lava): they are recorded for the report.
"""

from __future__ import annotations

import hashlib
import logging
from typing import Any, Mapping, Sequence

from phyagentos.protocol import Lesson, LessonsDoc, SessionRecord, Trial, Workspace
from phyagentos.protocol.lifecycle import utc_now

from .conditions import canonical
from .lessons import count_outcome
from .lessons import keep_refs as _keep

__all__ = ["diagnose_death", "DeathBook", "DEATH_CAUSES", "SURVIVAL_KEYS", "correction_for", "correction_acted",
           "trial_arm", "trial_decision", "session_steps", "TRIAL_ALPHA", "TRIAL_MIN_STEPS", "TRIAL_MIN_DEATHS"]

logger = logging.getLogger(__name__)

DEATH_CAUSES = ("death.lava", "death.zombie_asleep", "death.zombie", "death.zombie_night", "death.skeleton",
                "death.thirst", "death.starvation", "death.exhaustion", "death.unknown")
#: Survival reflex defaults of the game skills (trees/game_*.yaml), vital units 0..9.
_DEFAULTS = {"drink_below": 4, "food_below": 4, "energy_below": 3, "health_below": 5}
#: threshold -> (the reflex mode it triggers, the vital it compares)
_REFLEX_MODE = {"drink_below": ("drink", "drink"), "food_below": ("eat", "food"), "energy_below": ("rest", "energy"),
                "health_below": ("retreat", "health")}
#: The skill parameters survival lessons set (every game skill's reflex thresholds).
SURVIVAL_KEYS = frozenset(_DEFAULTS)
#: One-sided significance of a trial's decision (module doc: repeated looks, hence small).
TRIAL_ALPHA = 0.05
#: Game steps each arm must have played before a trial decides (about three episodes).
TRIAL_MIN_STEPS = 2000
#: Deaths both arms together must have had before a trial decides.
TRIAL_MIN_DEATHS = 4


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


def trial_arm(run_id: str, lesson_id: str) -> bool:
    """True when run ``run_id`` is in the ``with`` arm of lesson ``lesson_id``'s trial
    (half of all runs, by the first byte of a SHA-1; independent across lessons)."""
    return hashlib.sha1(f"{run_id}/{lesson_id}".encode()).digest()[0] % 2 == 0


def session_steps(trace: Sequence[Mapping[str, Any]]) -> int:
    """Game steps a session played: the span of the ``step`` stamps in its trace (0 without any)."""
    steps = [int(r["step"]) for r in trace if isinstance(r.get("step"), (int, float))]
    return max(steps) - min(steps) + 1 if steps else 0


def trial_decision(trial: Trial) -> tuple[str, float | None]:
    """``("verified" | "refuted" | "open", p)`` for ``trial`` (module doc).

    ``p`` is the one-sided p-value of the direction the data lean to (fewer deaths per
    step with the correction -> the ``less`` tail), ``None`` before the trial has
    :data:`TRIAL_MIN_STEPS` steps per arm and :data:`TRIAL_MIN_DEATHS` deaths."""
    n = trial.deaths_with + trial.deaths_without
    if min(trial.steps_with, trial.steps_without) < TRIAL_MIN_STEPS or n < TRIAL_MIN_DEATHS:
        return "open", None
    from scipy.stats import binomtest  # noqa: PLC0415 - only when a trial is decided

    share = trial.steps_with / (trial.steps_with + trial.steps_without)
    fewer = binomtest(trial.deaths_with, n, share, alternative="less").pvalue
    more = binomtest(trial.deaths_with, n, share, alternative="greater").pvalue
    if fewer <= TRIAL_ALPHA:
        return "verified", float(fewer)
    if more <= TRIAL_ALPHA:
        return "refuted", float(more)
    return "open", float(min(fewer, more))


def _lid(cause: str, revision: Mapping[str, Any]) -> str:
    return "D" + hashlib.sha1(canonical(["death", cause, revision]).encode()).hexdigest()[:10]


class DeathBook:
    """Death lessons in LESSONS.md of ``workspace`` and their trials (module doc)."""

    def __init__(self, workspace: Workspace, *, embodiment: str = "crafter"):
        self.workspace = workspace
        self.scope = {"embodiment": embodiment, "skill": "game_*", "object_class": None, "risk_factors": []}

    def applicable(self, *, run_id: str | None = None) -> list[tuple[Lesson, str]]:
        """Survival lessons for a new game session of run ``run_id``, ``(lesson, role)``:

        - ``"verified"``: a verified lesson (its trial found fewer deaths with it), applied;
        - ``"with"`` / ``"without"``: an open candidate and the arm ``run_id`` is in
          (applied only in ``with``); only when ``run_id`` is given, i.e. while memory
          learns. A frozen measurement passes ``None``: candidates are not applied.

        Refuted candidates are never returned."""
        doc: LessonsDoc = self.workspace.read("LESSONS").data
        out = [(entry, "verified") for entry in doc.lessons if entry.scope == self.scope and entry.revision and entry.verified]
        if run_id is not None:
            out += [(c, "with" if trial_arm(run_id, c.id) else "without") for c in doc.candidates
                    if c.scope == self.scope and c.revision and c.refutations == 0]
        return out

    def learn(self, session: SessionRecord, trace: Sequence[Mapping[str, Any]], evidence: Sequence[str] = ()) -> list[str]:
        """Record ``session``'s death (if any) and add the session to the trials it was
        assigned to (its context: an applied item is the ``with`` arm, a held-back one
        the ``without`` arm); decide every trial it touched."""
        found = diagnose_death(trace)
        items = [i for i in (session.context.items if session.context else ()) if i.kind == "lesson"]
        arms = {i.id: bool(i.applied) for i in items}
        if found is None and not arms:
            return []
        sid, now = session.session_id, utc_now()
        steps, died = session_steps(trace), found is not None
        touched: list[str] = []

        def apply(doc: LessonsDoc) -> None:
            for item in list(doc.candidates):
                if item.id not in arms or item.scope != self.scope or item.refutations:
                    continue
                t = item.trial or Trial()
                if arms[item.id]:
                    t.steps_with += steps
                    t.deaths_with += int(died)
                    t.sessions_with += 1
                    t.acted_with += int(correction_acted(item.revision, trace))
                else:
                    t.steps_without += steps
                    t.deaths_without += int(died)
                    t.sessions_without += 1
                outcome, t.p_value = trial_decision(t)
                item.trial = t
                item.updated_at = now
                if outcome == "verified":
                    doc.candidates = [c for c in doc.candidates if c.id != item.id]
                    item.verified = True
                    count_outcome(item, sid, confirmed=True, now=now)
                    doc.lessons.append(item)
                    logger.info("survival lesson %s verified by its trial (p=%.3f): %s", item.id, t.p_value,
                                item.correction)
                elif outcome == "refuted":
                    count_outcome(item, sid, confirmed=False, now=now)
                    logger.info("survival lesson %s refuted by its trial (p=%.3f)", item.id, t.p_value)
                touched.append(item.id)
            if found is None:
                return
            cause, facts = found
            revision = correction_for(cause, session.parameters)
            lid = _lid(cause, revision)
            existing = next((entry for entry in [*doc.lessons, *doc.candidates] if entry.id == lid), None)
            text = (f"died at step {facts['step']} ({cause[6:].replace('_', ' ')}; next to {facts['adjacent'] or 'nothing'}, "
                    f"vitals {facts['vitals']})")
            fix = ", ".join(f"{k}={v}" for k, v in sorted(revision.items())) or "no parameter (avoid it)"
            if existing is None:
                doc.candidates.append(Lesson(id=lid, objective="survive a Crafter episode", evidence=list(evidence),
                                             cause=cause, correction=f"{text}: set {fix}", scope=dict(self.scope),
                                             provenance=[sid], strategy="survival", revision=revision,
                                             trial=Trial() if revision else None, updated_at=now))
            else:
                existing.provenance = _keep(existing.provenance, sid)
                existing.evidence = _keep(existing.evidence, *evidence)
                existing.updated_at = now
            touched.append(lid)
            logger.info("session %s: %s -> %s", sid, cause, fix)

        self.workspace.update("LESSONS", apply)
        return touched
