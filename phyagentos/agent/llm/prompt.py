"""ModelContextBuilder: what a model is told, within a token budget, and a record of it.

Sections, in order of priority (the last ones are dropped first when the budget is
exceeded): the request, the environment (entities the plan may name), the capabilities
(skills and targets), prior attempts (evidence summaries of this node's failures) and
retrieved lessons. Tokens are estimated as ``ceil(chars / 4)`` (a common rule of thumb
for English BPE vocabularies; SmolLM2's tokenizer measures 3.6-4.2 chars per token on
these prompts), so the budget is approximate by design. :class:`ModelContext` records
which sections and how many items of each went in, and which were dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

__all__ = ["ModelContext", "ModelContextBuilder", "estimate_tokens"]


def estimate_tokens(text: str) -> int:
    """Approximate token count of ``text`` (``ceil(len / 4)``)."""
    return math.ceil(len(text) / 4)


@dataclass(frozen=True)
class ModelContext:
    """The assembled user message and what it holds.

    Attributes:
        text: the message.
        injected: section -> number of items that went in.
        dropped: section -> number of items left out for the budget.
        tokens: estimated tokens of ``text``.
        budget: the token budget it was built for.
    """

    text: str
    injected: dict[str, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    tokens: int = 0
    budget: int = 0

    def to_dict(self) -> dict[str, Any]:
        return {"injected": dict(self.injected), "dropped": dict(self.dropped), "tokens": self.tokens,
                "budget": self.budget}


class ModelContextBuilder:
    """Assembles a model's user message from sections within ``budget_tokens``.

    Args:
        budget_tokens: upper bound on the message's estimated tokens.
    """

    ORDER = ("environment", "capabilities", "prior_attempts", "lessons", "request")
    #: dropped first -> last
    DROP_ORDER = ("lessons", "prior_attempts", "capabilities")

    def __init__(self, budget_tokens: int = 700):
        self.budget = int(budget_tokens)

    def build(self, *, request: str, environment: Sequence[str], capabilities: Sequence[str] = (),
              prior_attempts: Sequence[str] = (), lessons: Sequence[str] = (),
              headings: dict[str, str] | None = None) -> ModelContext:
        """Join the sections (a heading line, then one line per item); drop items of the lowest-priority
        sections, last item first, until the estimate fits. The request and environment are never dropped."""
        heads = {"environment": "Scene:", "capabilities": "Skills:", "prior_attempts": "Earlier attempts:",
                 "lessons": "Lessons:", "request": "Request:"}
        heads.update(headings or {})
        items = {"environment": list(environment), "capabilities": list(capabilities),
                 "prior_attempts": list(prior_attempts), "lessons": list(lessons), "request": [request]}
        dropped: dict[str, int] = {}

        def render() -> str:
            parts = []
            for sec in self.ORDER:
                if items[sec]:
                    if sec == "request":
                        parts.append(f"{heads[sec]} {items[sec][0]}")
                    else:
                        parts.append("\n".join([heads[sec]] + [f"- {x}" for x in items[sec]]))
            return "\n".join(parts)

        text = render()
        for sec in self.DROP_ORDER:
            while estimate_tokens(text) > self.budget and items[sec]:
                items[sec].pop()
                dropped[sec] = dropped.get(sec, 0) + 1
                text = render()
        return ModelContext(text=text, injected={s: len(v) for s, v in items.items() if v}, dropped=dropped,
                            tokens=estimate_tokens(text), budget=self.budget)
