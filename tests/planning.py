"""Shared set-up of the Goal Planner tests: a planner over a fresh workspace's targets, and
what perception would have left in ENVIRONMENT.md for a test scene."""

from __future__ import annotations

from pathlib import Path

from phyagentos.agent.planner import GoalPlanner
from phyagentos.app.orchestrator import skill_names
from phyagentos.llm import make_client
from phyagentos.protocol import Workspace


def make_planner(directory: Path) -> GoalPlanner:
    """A GoalPlanner with the offline model, the shipped skills and the targets of a workspace
    created in ``directory``."""
    ws = Workspace.create(directory)
    targets = [t.model_dump(mode="json") for t in ws.read("TARGETS").data.targets]
    return GoalPlanner(make_client(), skills=skill_names(), targets=targets)


def seen(scene: dict) -> list[dict]:
    """ENVIRONMENT.md entities as a perception would have left them for ``scene``'s objects
    (test input): each object at its declared (x, y), 2 cm up, with its colour."""
    return [{"name": o["name"], "kind": "object", "position": [*o["position"][:2], 0.02], "rgba": o.get("rgba")}
            for o in scene["objects"]]
