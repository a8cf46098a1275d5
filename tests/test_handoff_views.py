"""Views stay off the hand-off of ``phyagentos run`` (issue 12, round 4).

Between a verdict and the next session's first actuation the agent's thread and the
supervisor's share one interpreter. ``drive_run`` therefore lets the coordinator defer
the TASK.md rewrite (a view, not fsynced, rebuilt from the session files) of a step
that submitted until the submitted session has been claimed and started; the view is
current again before the run returns.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from phyagentos.protocol import Workspace

HOLD = Path(__file__).resolve().parent.parent / "goal_graphs" / "hold.yaml"


def _chain(path: Path, n: int) -> Path:
    nodes = [{"id": f"h{i}", "skill": "hold", "params": {"duration_s": 0.0},
              "accept": {"still": {"max_joint_motion_rad": 0.01}},
              "depends_on": [f"h{i - 1}"] if i else []} for i in range(n)]
    path.write_text(yaml.safe_dump({"version": 1, "name": "chain", "defaults": {"target": "franka_tabletop"},
                                    "nodes": nodes}))
    return path


def _agent(ws: Workspace, graph: Path):
    from phyagentos.agent.agent_loop import load_run_graph
    from phyagentos.agent.coordinator import AgentCoordinator
    from phyagentos.orchestrator import _register_run, skill_names

    run = _register_run(ws, graph, seed=0, target=None)
    return AgentCoordinator(ws, load_run_graph(ws, run.run_id, skills=skill_names()), run_id=run.run_id), run


def test_a_deferring_step_leaves_task_md_stale_but_knows_what_it_submitted(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    agent, run = _agent(ws, HOLD)
    agent.defer_task_view = True
    assert agent.step() == 1
    assert agent.task_view_stale
    assert ws.read("TASK").data.run_id != run.run_id  # not rewritten by the step
    # the step's sessions include the one it submitted, without listing them again
    assert [s.state for s in agent.last_sessions] == ["pending"]
    assert {s.session_id for s in agent.last_sessions} == {sid for sid, _, _ in ws.active_sessions(run_id=run.run_id)}
    agent.write_task()
    assert not agent.task_view_stale
    task = ws.read("TASK").data
    assert task.run_id == run.run_id and [n.state for n in task.nodes] == ["running"]


def test_a_step_that_submits_nothing_writes_task_md_even_when_deferring(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    agent, run = _agent(ws, HOLD)
    agent.defer_task_view = True
    agent.step()
    assert agent.step() == 0  # nothing new
    assert not agent.task_view_stale and ws.read("TASK").data.run_id == run.run_id


def test_drive_run_defers_task_md_past_the_claim_and_leaves_it_current(tmp_path, monkeypatch):
    from phyagentos.agent.coordinator import AgentCoordinator
    from phyagentos.orchestrator import run_goal_graph

    ws_dir = tmp_path / "ws"
    written: list[set[str]] = []  # states of the run's active sessions whenever a deferred view is written
    original = AgentCoordinator.write_task

    def spy(self):
        written.append({state for _, state, _ in self.workspace.active_sessions(run_id=self.run_id)})
        original(self)

    monkeypatch.setattr(AgentCoordinator, "write_task", spy)
    report = run_goal_graph(_chain(tmp_path / "chain.yaml", 3), ws_dir)
    assert report.succeeded
    assert written, "drive_run never deferred a TASK.md rewrite"
    # never while a submitted session still waited to be claimed or started
    assert all(not states & {"pending", "claimed", "preflight_checking"} for states in written), written
    task = Workspace.open(ws_dir).read("TASK").data
    assert task.run_id == report.run_id and [n.state for n in task.nodes] == ["succeeded"] * 3
