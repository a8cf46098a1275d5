"""The reach query: the Agent plane asks the Runtime whether a target's arm reaches poses.

The Agent plane cannot run IK (it does not import the Runtime plane); the SkillRuntime-
Target Selector states what a node must reach as a :class:`ReachQuery` and a reach oracle
answers a :class:`ReachAnswer`. The composition root wires the Runtime's answer
(:func:`phyagentos.runtime.reach_query.answer_reach_query`: IK on the target's own model,
as the graph preflight runs it) into the Goal Planner and the ToolRegistry (tool
``query_reach``), so an in-process or MCP agent asks the same question the same way.
"""

from __future__ import annotations

from typing import Any, Literal, Protocol

from pydantic import Field

from .schemas import ProtocolModel

__all__ = ["ReachQuery", "ReachAnswer", "ReachOracle"]


class ReachQuery(ProtocolModel):
    """What one node must reach on one target.

    Attributes:
        target: TARGETS.md name; ``driver`` its driver.
        scene: the scene the target is built on (objects, regions, obstacles as declared).
        positions: object name -> (x, y) in the world frame, m, as *perceived*; objects of
            the scene not listed here are not checked (their position is unknown).
        pick: the object picked (its top-down grasp and pre-grasp must solve), or ``None``.
        place: ``[object, destination]`` (a region or another object to stack on): the
            held object's place and pre-place pose must solve, or ``None``.
    """

    target: str
    driver: str
    scene: dict[str, Any] = Field(default_factory=dict)
    positions: dict[str, list[float]] = Field(default_factory=dict)
    pick: str | None = None
    place: list[str] | None = None


class ReachAnswer(ProtocolModel):
    """The Runtime's answer: ``status`` ``reachable``/``unreachable``/``unknown`` (not checked: a
    position not perceived yet) or ``unsupported`` (the target's driver cannot build the scene), and why."""

    status: Literal["reachable", "unreachable", "unknown", "unsupported"]
    reasons: list[str] = Field(default_factory=list)
    checked_by: str = Field("ik", description="What answered: ik (the target's model), or envelope.")


class ReachOracle(Protocol):
    """Answers reach queries (a callable)."""

    def __call__(self, query: ReachQuery) -> ReachAnswer: ...
