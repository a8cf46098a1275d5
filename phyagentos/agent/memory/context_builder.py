"""ContextBuilder: retrieve memory for a new session and record what it injected.

Before the Session Compiler writes a first-attempt session, the ContextBuilder computes
the session's :class:`~phyagentos.agent.memory.conditions.Conditions` (goal, skill,
target and embodiment, object and risk factors) and retrieves, in order of authority:

1. procedures from SKILL.md learned on a similar object (promoted, repeatedly verified):
   their parameters are applied;
2. verified lessons from LESSONS.md learned on a similar object: a correction of a cause
   that follows the object (a slip, a missed grasp, a place off; ``OBJECT_CAUSES``) is
   applied, most similar then most confirmed first, a parameter set by an earlier item
   winning; a correction of a cause that belongs to the scene (a collision, a pose out of
   reach, an unseen object) is only held in the context (``held``) and becomes the first
   revision if that cause recurs (:class:`~phyagentos.agent.recovery.RecoveryPlanner`);
3. patterns from KNOWLEDGE.md learned on a similar object: recorded as context; the best
   one's parameters are applied only when nothing above applied and it is well
   established (:data:`KNOWLEDGE_MIN_SUCCESSES` successes, rate >= :data:`KNOWLEDGE_MIN_RATE`).

Only the skill's optional (strategy) parameters are ever set, and never one the goal
graph node sets itself: the author's explicit choice wins over memory. What was
retrieved, what it set and the session ids it was verified on go into the session's
``context`` (:class:`~phyagentos.protocol.SessionContext`), so every injected item is
traceable. "Similar" is :func:`~.similarity.similarity` at least
:data:`~.similarity.MIN_SIMILARITY`: same embodiment, skill, declared category and shape,
extents within perception's spread, the item's situational risk factors among the
session's. Unverified candidates are never retrieved.
"""

from __future__ import annotations

import logging
from typing import Any, Mapping

from phyagentos.protocol import ContextItem, SessionContext, Workspace
from phyagentos.protocol.lifecycle import utc_now

from ..skill_catalog import SkillInfo, skill_catalog
from .conditions import Conditions, session_conditions
from .game import game_context_items
from .knowledge import KnowledgeBase
from .lessons import LessonBook, held_correction
from .observed import ObservedObject
from .similarity import MIN_SIMILARITY, similarity

__all__ = ["ContextBuilder", "KNOWLEDGE_MIN_SUCCESSES", "KNOWLEDGE_MIN_RATE", "MAX_ITEMS"]

logger = logging.getLogger(__name__)

KNOWLEDGE_MIN_SUCCESSES = 3
KNOWLEDGE_MIN_RATE = 0.75
#: At most this many items of each kind are recorded in a session's context.
MAX_ITEMS = 5


class ContextBuilder:
    """Builds session contexts from the memory documents of ``workspace``.

    Args:
        workspace: the protocol workspace (LESSONS.md, KNOWLEDGE.md, SKILL.md, TARGETS.md).
        use_memory: retrieve and apply memory; ``False`` records the conditions only
            (a run "with empty memory").
        skills: skill name -> :class:`SkillInfo` (default: the shipped manifests).
        trials: memory is learning: open survival candidates are applied or held back
            by the run's trial arm (``memory/deaths.py``); ``False`` (a frozen
            measurement) applies only verified lessons.
    """

    def __init__(self, workspace: Workspace, *, use_memory: bool = True, skills: Mapping[str, SkillInfo] | None = None,
                 trials: bool = True):
        self.workspace = workspace
        self.use_memory = use_memory
        self.trials = trials
        self.skills = dict(skills) if skills is not None else skill_catalog()
        self.lessons = LessonBook(workspace)
        self.knowledge = KnowledgeBase(workspace)

    def conditions(self, *, goal: str, skill: str, target: str, parameters: Mapping[str, Any],
                   scene: Mapping[str, Any] | None, observed: ObservedObject | None = None) -> Conditions:
        """The session's conditions; the embodiment is the target's driver in TARGETS.md.

        ``scene`` is read through its declared descriptors only; ``observed`` is what
        earlier sessions of the run perceived and measured of the object."""
        spec = next((t for t in self.workspace.read("TARGETS").data.targets if t.name == target), None)
        embodiment = spec.driver if spec is not None else target
        return session_conditions(goal=goal, skill=skill, target=target, embodiment=embodiment,
                                  parameters=parameters, scene=scene, observed=observed)

    def build(self, *, goal: str, skill: str, target: str, parameters: Mapping[str, Any],
              scene: Mapping[str, Any] | None, observed: ObservedObject | None = None,
              run_id: str | None = None) -> tuple[dict[str, Any], SessionContext]:
        """``(parameters to run with, context to record)`` for a new session.

        Args:
            goal: ``<goal graph name>/<node id>``.
            skill, target: the node's skill and target.
            parameters: the node's own parameters (never overridden).
            scene: the goal graph's scene mapping (only its declared descriptors are read).
            observed: what earlier sessions of the run observed of the object.
            run_id: the session's run (assigns it to the arms of open trials).
        """
        cond = self.conditions(goal=goal, skill=skill, target=target, parameters=parameters, scene=scene,
                               observed=observed)
        context = SessionContext(conditions=cond.to_dict(), risk_factors=list(cond.risk_factors), built_at=utc_now())
        if not self.use_memory:
            return dict(parameters), context
        info = self.skills.get(skill)
        settable = (info.optional if info is not None else frozenset()) - set(parameters)
        applied: dict[str, Any] = {}
        items: list[ContextItem] = []

        def take(values: Mapping[str, Any]) -> dict[str, Any]:
            took = {k: v for k, v in values.items() if k in settable and k not in applied}
            applied.update(took)
            return took

        procedures = sorted(((score, p) for p in self.workspace.read("SKILL").data.procedures
                             if (score := similarity(p.conditions, cond)) >= MIN_SIMILARITY),
                            key=lambda pair: pair[0], reverse=True)
        for score, proc in procedures[:MAX_ITEMS]:
            items.append(ContextItem(kind="procedure", id=proc.name, summary=f"{proc.description} (similarity {score:.2f})",
                                     provenance=list(proc.provenance), applied=take(proc.parameters)))
        for score, lesson in self.lessons.retrieve_scored(cond)[:MAX_ITEMS]:
            held = held_correction(lesson)
            summary = (f"{lesson.cause} -> {lesson.correction} (confirmed {lesson.confirmations}x, "
                       f"refuted {lesson.refutations}x; similarity {score:.2f}"
                       f"{'; held until ' + lesson.cause + ' recurs' if held else ''})")
            items.append(ContextItem(kind="lesson", id=lesson.id, summary=summary, provenance=list(lesson.verified_by),
                                     applied={} if held else take(lesson.revision), held=held))
        for item, values in game_context_items(self.workspace, skill=skill, parameters=parameters,
                                                  run_id=run_id if self.trials else None):
            items.append(item.model_copy(update={"applied": take(values)}))  # recipes, survival (memory/game.py)
        for n, entry in enumerate(self.knowledge.retrieve(cond)[:MAX_ITEMS]):
            established = (entry.successes >= KNOWLEDGE_MIN_SUCCESSES
                           and entry.successes >= KNOWLEDGE_MIN_RATE * entry.attempts)
            sets = take(entry.parameters) if n == 0 and not applied and established else {}
            items.append(ContextItem(kind="knowledge", id=entry.id,
                                     summary=f"{entry.pattern}: {entry.successes}/{entry.attempts} successes",
                                     provenance=list(entry.provenance), applied=sets))
        context = context.model_copy(update={"items": items, "parameters": dict(applied)})
        if applied:
            logger.info("context for %s: memory sets %s", goal, applied)
        return {**dict(parameters), **applied}, context
