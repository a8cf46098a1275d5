"""Factories of the Agent plane's thinking parts, wired to the Runtime where they ask it
(the IK reach oracle): the Goal Planner, the library planner, the revisers, and the default
scene a request is planned on. Used by ``phyagentos plan``/``run`` and the MCP server.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from phyagentos.errors import GoalGraphError
from phyagentos.yamlsource import read_yaml

__all__ = ["default_scene", "load_scene", "perceived_entities", "make_planner", "make_library_planner",
           "make_reviser"]


def _reach_oracle(root: Path):
    """The Runtime's IK reach oracle for the workspace at ``root``
    (:func:`phyagentos.runtime.reach_query.answer_reach_query`), imported on its first
    question: ``phyagentos run`` wires it into the reviser and must not load the motion
    stack in its own process (the runner's forkserver has it)."""

    def ask(*args, **kwargs):
        from phyagentos.runtime.reach_query import answer_reach_query  # noqa: PLC0415

        return answer_reach_query(*args, root=root, **kwargs)

    return ask


def default_scene() -> dict[str, Any]:
    """The tabletop scene of ``phyagentos/data/goal_graphs/pick_and_place.yaml``."""
    from phyagentos.resources import goal_graphs_dir  # noqa: PLC0415

    return load_scene(goal_graphs_dir() / "pick_and_place.yaml")


def load_scene(path: str | Path) -> dict[str, Any]:
    """A scene mapping from ``path``: a goal graph (its ``scene``) or a bare scene (``objects``/``regions``)."""
    try:
        data = read_yaml(path, error=GoalGraphError)
    except OSError as exc:
        raise GoalGraphError(f"cannot read scene: {exc}", path=path) from exc
    if isinstance(data, dict) and isinstance(data.get("scene"), dict):
        return data["scene"]
    if isinstance(data, dict) and ("objects" in data or "regions" in data):
        return data
    raise GoalGraphError("expected a scene mapping (objects, regions, obstacles) or a goal graph with a 'scene'",
                         path=path)


def perceived_entities(workspace) -> list[dict[str, Any]]:
    """ENVIRONMENT.md's entities (what the runtime last perceived) as plain mappings; empty before any run."""
    return [e.model_dump(mode="json") for e in workspace.read("ENVIRONMENT").data.entities]


def make_planner(workspace, *, client=None):
    """A GoalPlanner over ``workspace``'s targets and the shipped skills, with the configured model; its
    selector asks the Runtime's IK about reach (:func:`phyagentos.runtime.reach_query.answer_reach_query`)."""
    from phyagentos.agent.planner import GoalPlanner  # noqa: PLC0415
    from phyagentos.app.orchestrator import skill_names  # noqa: PLC0415
    from phyagentos.llm import load_llm_config, make_client  # noqa: PLC0415

    targets = [t.model_dump(mode="json") for t in workspace.read("TARGETS").data.targets]
    client = client or make_client(load_llm_config(workspace.root))
    # Verified lessons, most confirmed first: the ContextBuilder injects them within its budget (lowest priority).
    verified = sorted((x for x in workspace.read("LESSONS").data.lessons if x.verified),
                      key=lambda x: -x.confirmations)
    lessons = [f"{x.cause}: {x.correction} ({x.confirmations} confirmation(s))" for x in verified[:5]]
    return GoalPlanner(client, skills=skill_names(), targets=targets, lessons=lessons,
                       reach=_reach_oracle(workspace.root))


def make_library_planner(workspace, *, client=None):
    """A LibraryPlanner (a request as one goal of a task library) with the configured model."""
    from phyagentos.agent.library_planner import LibraryPlanner  # noqa: PLC0415
    from phyagentos.app.orchestrator import skill_names  # noqa: PLC0415
    from phyagentos.llm import load_llm_config, make_client  # noqa: PLC0415

    targets = [t.name for t in workspace.read("TARGETS").data.targets]
    return LibraryPlanner(client or make_client(load_llm_config(workspace.root)), skills=skill_names(),
                          targets=targets)


def make_reviser(kind: str, workspace_dir: str | Path):
    """The rule ladder, or a ModelReviser (the configured model) with the ladder as fallback; both with a
    TargetChooser that asks the Runtime's IK, so a node whose arm cannot reach (``ik_unreachable``) or plan
    it moves to another capable target that reaches it."""
    from phyagentos.agent.recovery import RecoveryPlanner, targets_capabilities  # noqa: PLC0415
    from phyagentos.agent.retarget import TargetChooser  # noqa: PLC0415
    from phyagentos.protocol import Workspace  # noqa: PLC0415

    ws = Workspace.create(workspace_dir)
    chooser = TargetChooser(ws, reach=_reach_oracle(ws.root))
    caps = targets_capabilities(ws)
    if kind == "rules":
        return RecoveryPlanner(retarget=chooser, capabilities=caps)
    from phyagentos.agent.reviser import ModelReviser  # noqa: PLC0415
    from phyagentos.llm import load_llm_config, make_client  # noqa: PLC0415

    return ModelReviser(make_client(load_llm_config(workspace_dir)),
                        fallback=RecoveryPlanner(retarget=chooser, capabilities=caps), retarget=chooser,
                        capabilities=caps)
