"""``schedule: file_order``: the coordinator submits one ready node at a time, first in file order."""

from __future__ import annotations

import yaml
from supervisor_util import make_workspace

from phyagentos.agent.coordinator import AgentCoordinator
from phyagentos.agent.goal_graph import parse_goal_graph


def _graph(schedule: str | None):
    doc = {"version": 1, "name": "g", "nodes": [
        {"id": n, "skill": "noop", "target": "franka_tabletop", "params": {}, "accept": {}} for n in ("a", "b", "c")]}
    doc["nodes"][2]["depends_on"] = ["a"]
    if schedule:
        doc["schedule"] = schedule
    return parse_goal_graph(yaml.safe_dump(doc, sort_keys=False), skills=["noop"], targets=["franka_tabletop"])


def _nodes(ws, run_id):
    return sorted(s.node for s in ws.list_sessions(run_id=run_id))


def test_eager_schedule_submits_every_ready_node_at_once(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    AgentCoordinator(ws, _graph(None), run_id="r-eager").step()
    assert _nodes(ws, "r-eager") == ["a", "b"]


def test_file_order_schedule_submits_the_first_ready_node_and_waits_for_it(tmp_path):
    ws = make_workspace(tmp_path / "ws")
    agent = AgentCoordinator(ws, _graph("file_order"), run_id="r-seq")
    agent.step()
    assert _nodes(ws, "r-seq") == ["a"]
    agent.step()  # a is still pending: nothing more is submitted
    assert _nodes(ws, "r-seq") == ["a"]
    (sid,) = [s.session_id for s in ws.list_sessions(run_id="r-seq")]
    ws.update_session(sid, lambda rec: setattr(rec, "state", "succeeded"))
    agent.step()
    # b and c are both ready now; b comes first in the file although c depends on what finished
    assert _nodes(ws, "r-seq") == ["a", "b"]
