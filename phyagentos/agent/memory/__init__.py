"""Epistemic memory: lessons (LESSONS.md), knowledge (KNOWLEDGE.md), promoted procedures
(SKILL.md), and the ContextBuilder that retrieves them for new sessions.

Only verified outcomes are consolidated: a correction becomes a lesson when a later
verdict confirms it, a pattern enters KNOWLEDGE.md when a verdict says it succeeded, a
procedure is promoted when it succeeded often enough from varied initial states.
"""

from .conditions import Conditions, risk_factors, scope_matches, session_conditions
from .context_builder import ContextBuilder
from .knowledge import KnowledgeBase
from .lessons import LessonBook
from .observed import ObservedObject, observe_object
from .promotion import PromotionPolicy, promote
from .similarity import MIN_SIMILARITY, similarity

__all__ = [
    "Conditions",
    "ContextBuilder",
    "KnowledgeBase",
    "LessonBook",
    "MIN_SIMILARITY",
    "ObservedObject",
    "observe_object",
    "PromotionPolicy",
    "promote",
    "risk_factors",
    "scope_matches",
    "session_conditions",
    "similarity",
]
