"""Composition root for ``phyagentos run``: both planes in one process.

This is the one place allowed to import the Agent and Runtime planes together.
They still meet only through the workspace: the agent loop writes sessions and
verdicts, the supervisor claims and runs sessions, and each reads the other's
output from the protocol files.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

from phyagentos.agent.coordinator import AgentCoordinator, SessionSummary
from phyagentos.agent.goal_graph import GoalGraph, load_goal_graph
from phyagentos.errors import SupervisorError
from phyagentos.protocol import Workspace
from phyagentos.resources import skills_dir, trees_dir
from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
from phyagentos.runtime.supervisor import WatchdogSupervisor

__all__ = ["RunReport", "load_graph_for", "run_goal_graph"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class RunReport:
    """Outcome of one run: its id, per-session rows and whether every node succeeded."""

    run_id: str
    workspace: Path
    goal_graph: str
    succeeded: bool
    node_states: dict
    sessions: list[SessionSummary]
    wall_time_s: float

    def to_dict(self) -> dict:
        return {
            "run_id": self.run_id,
            "workspace": str(self.workspace),
            "goal_graph": self.goal_graph,
            "succeeded": self.succeeded,
            "wall_time_s": round(self.wall_time_s, 3),
            "nodes": self.node_states,
            "sessions": [s.to_dict() for s in self.sessions],
        }


def load_graph_for(workspace: Workspace, path: str | Path, runtime: BuiltinSkillRuntime) -> GoalGraph:
    """Load and validate a goal graph against the workspace's targets and the skill registry."""
    targets = [t.name for t in workspace.read("TARGETS").data.targets]
    return load_goal_graph(path, skills=runtime.skills.names(), targets=targets)


def run_goal_graph(
    goal_graph: str | Path,
    workspace_dir: str | Path,
    *,
    seed: int | None = 0,
    target: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> RunReport:
    """Run ``goal_graph`` to completion in ``workspace_dir`` (created if needed).

    Args:
        goal_graph: path of the goal-graph YAML.
        workspace_dir: the workspace directory.
        seed: base seed of the run's sessions.
        target: if given, overrides every node's target (same graph, another embodiment).
        progress: called with a one-line message as sessions move.

    Raises:
        GoalGraphError: the goal graph is invalid.
        DocumentError: a protocol document in the workspace is malformed (left untouched).
        SupervisorError: the run stopped making progress before completing.
    """
    started = time.perf_counter()
    workspace = Workspace.create(workspace_dir)
    runtime = BuiltinSkillRuntime.from_dirs(skills_dir(), trees_dir())
    graph = load_graph_for(workspace, goal_graph, runtime)
    if target is not None:
        graph = replace(graph, nodes=tuple(replace(n, target=target) for n in graph.nodes))
    agent = AgentCoordinator(workspace, graph, seed=seed)
    supervisor = WatchdogSupervisor(workspace, runtime)
    say = progress or (lambda msg: None)
    say(f"run {agent.run_id}: {len(graph.nodes)} node(s) from {goal_graph}")
    try:
        agent.step()
        while not agent.done():
            ran = supervisor.run_once()
            acted = agent.step()
            if ran:
                states = agent.node_states()
                say("nodes: " + ", ".join(f"{n}={s}" for n, s in states.items()))
            if ran == 0 and acted == 0:
                raise SupervisorError(f"run {agent.run_id} stalled: node states {agent.node_states()}")
    finally:
        supervisor.close()
    return RunReport(
        run_id=agent.run_id,
        workspace=workspace.root,
        goal_graph=str(goal_graph),
        succeeded=agent.succeeded(),
        node_states=agent.node_states(),
        sessions=agent.summary(),
        wall_time_s=time.perf_counter() - started,
    )
