"""Drive a goal graph registered *without* the whole-graph check of ``validate``/``run``.

Since issue 11, ``phyagentos run`` refuses a graph whose object is out of reach before
anything moves. Tests of how the runtime and the Agent plane handle a failure that only
shows at run time (an IK failure, replans, a blocked subgraph) register such a graph
the way a hand-written run would get in, and drive it with the same loop as ``run``.
"""

from __future__ import annotations

import time
from pathlib import Path

from phyagentos.agent.agent_loop import load_run_graph
from phyagentos.agent.coordinator import AgentCoordinator
from phyagentos.app.orchestrator import RunReport, _register_run, drive_run
from phyagentos.protocol import Workspace
from phyagentos.resources import skill_dirs, tree_dirs
from phyagentos.runtime.builtin_runtime import BuiltinSkillRuntime
from phyagentos.runtime.supervisor import WatchdogSupervisor


def run_unchecked(graph: str | Path, workspace_dir: str | Path, *, seed: int = 0) -> RunReport:
    """As :func:`phyagentos.app.orchestrator.run_goal_graph`, without :func:`check_goal_graph`."""
    started = time.perf_counter()
    ws = Workspace.create(workspace_dir)
    runtime = BuiltinSkillRuntime.from_dirs(skill_dirs(), tree_dirs())
    run = _register_run(ws, graph, seed=seed, target=None)
    agent = AgentCoordinator(ws, load_run_graph(ws, run.run_id, skills=runtime.skills.names()), run_id=run.run_id,
                             seed=seed)
    supervisor = WatchdogSupervisor(ws, runtime)
    with ws.run_lock(run.run_id):
        try:
            drive_run(agent, supervisor)
        finally:
            supervisor.close()
        ws.runs.finish(run.run_id, succeeded=agent.succeeded())
    return RunReport(run_id=run.run_id, workspace=ws.root, goal_graph=str(graph), succeeded=agent.succeeded(),
                     node_states=agent.node_states(), sessions=agent.summary(),
                     wall_time_s=time.perf_counter() - started)
