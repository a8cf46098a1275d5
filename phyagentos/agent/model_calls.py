"""Model-call records in a session's context: every language-model call made for a session.

Three callers make model calls for a session, and each one's records reach the
session's :class:`~phyagentos.protocol.SessionContext` (``model_calls``), next to what
the memory ContextBuilder injected:

* the **Goal Planner**, before the run: the graph it wrote carries its calls in
  ``provenance.model_calls``; every root session of that graph keeps them;
* a **reviser** (:class:`~phyagentos.agent.reviser.ModelReviser`), at verification: its
  call is kept by the session it revised (:meth:`calls_for`) and, through
  :attr:`Revision.model_calls <phyagentos.protocol.Revision.model_calls>`, by the child that
  runs the revision;
* the **agent runtime** (``runtime: agent``), during the session: each step's record is
  in the trace (``agent_step`` entries with a ``model_call``), which is evidence; the
  coordinator copies them into the context when it verifies the attempt, with ``ref``
  naming the trace.

Each :class:`~phyagentos.protocol.ModelCallRecord` holds the prompt hash, model id,
sampling parameters, tokens, latency, raw output and what became of it.
"""

from __future__ import annotations

import logging
from typing import Any, Iterable, Mapping, Sequence

from phyagentos.protocol import ModelCallRecord, SessionContext
from phyagentos.protocol.lifecycle import utc_now

__all__ = ["planner_calls", "trace_calls", "with_calls"]

logger = logging.getLogger(__name__)


def _records(raw: Iterable[Any], *, where: str) -> list[ModelCallRecord]:
    out = []
    for item in raw:
        try:
            out.append(ModelCallRecord.model_validate(item))
        except ValueError as exc:  # a malformed record is reported, never silently kept
            logger.warning("%s: skipping a malformed model call record: %s", where, exc)
    return out


def planner_calls(provenance: Mapping[str, Any] | None) -> list[ModelCallRecord]:
    """The Goal Planner's calls from a goal graph's ``provenance`` (empty for a hand-written graph)."""
    if not provenance:
        return []
    return _records(provenance.get("model_calls") or [], where="goal graph provenance")


def trace_calls(trace: Sequence[Mapping[str, Any]], *, ref: str | None = None) -> list[ModelCallRecord]:
    """The agent runtime's calls from an evidence trace (``model_call`` of each ``agent_step``)."""
    raw = [dict(r["model_call"], ref=ref) for r in trace if isinstance(r, Mapping) and r.get("kind") == "agent_step"
           and isinstance(r.get("model_call"), Mapping)]
    return _records(raw, where=f"trace {ref}")


def with_calls(context: SessionContext | None, calls: Sequence[ModelCallRecord]) -> SessionContext | None:
    """A copy of ``context`` (a new empty one if ``None``) with ``calls`` appended; ``context`` itself if none."""
    if not calls:
        return context
    base = context if context is not None else SessionContext(built_at=utc_now())
    return base.model_copy(update={"model_calls": [*base.model_calls, *calls]})
