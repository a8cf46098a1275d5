"""A listing of a run races with the writers of its sessions: a session whose state hint is
renamed under the listing stays listed, and a step that saw a stale listing never submits a
node's session twice (the CI failure of a fleet partition drill: ``session ... already
exists`` ended the agent with exit code 2)."""

from __future__ import annotations

import logging

import yaml
from supervisor_util import make_workspace

from phyagentos.agent.coordinator import AgentCoordinator
from phyagentos.agent.goal_graph import parse_goal_graph
from phyagentos.protocol import SessionRecord, Workspace
from phyagentos.protocol.session_index import StateIndex

T0 = "2024-05-01T12:00:00Z"


def _record(sid: str, run_id: str) -> SessionRecord:
    return SessionRecord(session_id=sid, run_id=run_id, node="n", skill="noop", target="franka_tabletop",
                         parameters={}, created_at=T0, updated_at=T0)


def test_a_session_whose_hint_moves_during_a_listing_is_still_listed_for_its_run(tmp_path, monkeypatch):
    writer = Workspace.create(tmp_path / "ws")
    writer.submit_session(_record("r1-n-1", "r1"))
    writer.submit_session(_record("r2-n-1", "r2"))
    reader = Workspace.open(tmp_path / "ws")  # another process: no identity cached
    # the hint is renamed (claimed -> preflight_checking -> ...) between the listing's scan
    # and its read of the hint: the read finds no hint file
    monkeypatch.setattr(StateIndex, "identity", lambda self, sid, state=None: None)
    assert [r.session_id for r in reader.list_sessions(run_id="r1")] == ["r1-n-1"]
    assert [r.session_id for r in reader.list_sessions(run_id="r2")] == ["r2-n-1"]


def _graph():
    doc = {"version": 1, "name": "g", "nodes": [
        {"id": n, "skill": "noop", "target": "franka_tabletop", "params": {}, "accept": {}} for n in ("a", "b")]}
    return parse_goal_graph(yaml.safe_dump(doc, sort_keys=False), skills=["noop"], targets=["franka_tabletop"])


def test_a_step_on_a_listing_that_missed_a_session_does_not_submit_it_again(tmp_path, monkeypatch, caplog):
    ws = make_workspace(tmp_path / "ws")
    agent = AgentCoordinator(ws, _graph(), run_id="r-stale")
    assert agent.step() == 2
    before = {p.name: p.read_bytes() for p in (ws.root / "sessions").glob("*.md")}
    assert sorted(before) == ["r-stale-a-1.md", "r-stale-b-1.md"]
    real = agent.sessions
    listings = iter([[s for s in real() if s.node != "a"]])  # one listing misses node a's session
    monkeypatch.setattr(agent, "sessions", lambda: next(listings, None) or real())
    with caplog.at_level(logging.WARNING, logger="phyagentos.agent.session_compiler"):
        agent.step()
    assert "r-stale-a-1 was submitted already" in caplog.text
    # nothing was written again; each node still has its one session
    assert {p.name: p.read_bytes() for p in (ws.root / "sessions").glob("*.md")} == before
    assert sorted(s.session_id for s in real()) == ["r-stale-a-1", "r-stale-b-1"]
