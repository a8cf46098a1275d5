"""Who is the authority for what (docs/fleet.md, "Ownership").

- An **edge** is the authority for its targets' sessions while the Runtime plane holds
  them (submitted to verification: ``pending`` .. ``awaiting_verification``, and
  ``cancelling``/``cancelled``/``timed_out``/``rejected``/an abort), for TARGETS.md,
  ENVIRONMENT.md, RUNTIME_SIGNAL.md and the evidence bundles it writes.
- The **agent** is the authority for runs (``runs/``), TASK.md, memory (LESSONS,
  KNOWLEDGE, SKILL) and the verification of a session (``verifying`` and the verdicts
  ``succeeded``/``failed``/``awaiting_replan``/``replanned``).

Each side writes only what it is the authority for and keeps a replica of the rest; a
session's writers take turns (the edge hands it over by reaching
``awaiting_verification``), so a session's transitions form one append-only list.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from phyagentos.errors import FleetError, format_choices

__all__ = ["AGENT_DOCUMENTS", "AGENT_STATES", "EDGE_DOCUMENTS", "TargetMap", "authority_of_state"]

EDGE_DOCUMENTS = ("TARGETS", "ENVIRONMENT", "RUNTIME_SIGNAL")
AGENT_DOCUMENTS = ("TASK", "LESSONS", "KNOWLEDGE", "SKILL")
#: Session states the agent writes (verification and its outcome).
AGENT_STATES = frozenset({"verifying", "succeeded", "failed", "awaiting_replan", "replanned"})


def authority_of_state(state: str) -> str:
    """``"agent"`` for the states the agent writes, else ``"edge"``."""
    return "agent" if state in AGENT_STATES else "edge"


class TargetMap:
    """target name -> the edge that owns it, built from every edge's TARGETS.md replica.

    Raises (``add``):
        FleetError: two edges claim one target.
    """

    def __init__(self) -> None:
        self._owner: dict[str, str] = {}

    def add(self, edge: str, targets: Iterable[str]) -> None:
        for t in targets:
            other = self._owner.get(t)
            if other is not None and other != edge:
                raise FleetError(f"target {t!r} is owned by edge {other!r} and edge {edge!r}: give each target "
                                 "to one edge (fleet.yaml targets:)")
            self._owner[t] = edge

    def drop(self, edge: str) -> None:
        self._owner = {t: e for t, e in self._owner.items() if e != edge}

    def edge_of(self, target: str) -> str:
        """The edge owning ``target``.

        Raises:
            FleetError: no edge owns it (the message lists the owned targets).
        """
        try:
            return self._owner[target]
        except KeyError:
            raise FleetError(f"no edge owns target {target!r}; owned: {format_choices(self._owner) or 'none'}") from None

    def get(self, target: str) -> str | None:
        return self._owner.get(target)

    def as_dict(self) -> Mapping[str, str]:
        return dict(self._owner)
