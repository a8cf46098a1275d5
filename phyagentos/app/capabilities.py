"""What each target can act on, read from TARGETS.md, and the rule ladder that respects it.

A revision never asks a target for a parameter its hand or arm cannot take (a grip force on
LIBERO's Panda hand, which closes on position only): :class:`~phyagentos.agent.recovery.RecoveryPlanner`
leaves such parameters out given the lookup made here.
"""

from __future__ import annotations

from typing import Callable

from phyagentos.agent.recovery import RecoveryPlanner
from phyagentos.protocol import Workspace

__all__ = ["target_capabilities", "rule_reviser"]


def target_capabilities(workspace: Workspace) -> Callable[[str], frozenset[str] | None]:
    """Target name -> its TARGETS.md ``capabilities`` (read when asked: TARGETS.md may change
    while a run goes on); ``None`` for a target TARGETS.md does not list."""

    def lookup(name: str) -> frozenset[str] | None:
        spec = next((t for t in workspace.read("TARGETS").data.targets if t.name == name), None)
        return frozenset(spec.capabilities) if spec is not None else None

    return lookup


def rule_reviser(workspace: Workspace) -> RecoveryPlanner:
    """The rule ladder for ``workspace``: a revision leaves out the parameters a node's target
    cannot act on, by its TARGETS.md ``capabilities``; no re-target. ``run_goal_graph``'s
    default reviser, so the bench's runs get it too."""
    return RecoveryPlanner(capabilities=target_capabilities(workspace))
