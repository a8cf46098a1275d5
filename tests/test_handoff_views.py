"""Views stay off the hand-off of ``phyagentos run`` (issue 12, round 4).

Between a verdict and the next session's first actuation the agent's thread and the
supervisor's share one interpreter. ``drive_run`` therefore defers the two views it
rewrites there (neither fsynced, both rebuilt from the session files): the
coordinator's TASK.md rewrite of a step that submitted, and the SESSIONS.md entry of
every session write of either thread (``Workspace.defer_index``, one pending set shared
by the agent's and the supervisor's Workspace objects), until the submitted session has
been claimed and started; both are current again before the run returns. A deferred entry
never overwrites a later write of its session, and ``reconcile`` rebuilds a view that
a killed writer left behind.

Two-process mode (``watch`` + ``agent``) defers SESSIONS.md the same way in each process:
the supervisor rewrites it once the claimed session was started or a step did nothing
(never between a claim and its start), the agent loop before it waits; both leave it
current when idle and when they stop.

A verdict's LOG.md line is appended after the sessions its step submitted (in ``run``,
once they started, with TASK.md); an agent that dies before appending it leaves the line
to the next agent of the run, which appends it once, from the session file.
"""

from __future__ import annotations

import threading
from pathlib import Path

import yaml
from supervisor_util import Drill, submit, wait_for

from phyagentos.protocol import SessionRecord, Workspace, utc_now_iso
from phyagentos.protocol.lifecycle import SessionLifecycle
from phyagentos.resources import goal_graphs_dir

HOLD = goal_graphs_dir() / "hold.yaml"


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
    from phyagentos.app.orchestrator import _register_run, skill_names

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
    from phyagentos.app.orchestrator import drive_run
    from phyagentos.runtime.supervisor import SupervisorConfig, WatchdogSupervisor

    ws = Workspace.create(tmp_path / "ws")
    agent, run = _agent(ws, _chain(tmp_path / "chain.yaml", 3))
    written: list[set[str]] = []  # states of the run's active sessions whenever a deferred view is written
    original = AgentCoordinator.write_task

    def spy(self):
        written.append({state for _, state, _ in self.workspace.active_sessions(run_id=self.run_id)})
        original(self)

    monkeypatch.setattr(AgentCoordinator, "write_task", spy)
    # a long poll interval: no quiet-interval catch-up (e.g. while the first runner starts)
    supervisor = WatchdogSupervisor(ws, config=SupervisorConfig(poll_interval_s=60.0))
    try:
        drive_run(agent, supervisor)
    finally:
        supervisor.close()
    assert agent.succeeded()
    assert len(written) >= 3, written  # once per submitted session, after its start
    # never while a submitted session still waited to be claimed or started
    assert all(not states & {"pending", "claimed", "preflight_checking"} for states in written), written
    done = Workspace.open(ws.root)
    task = done.read("TASK").data
    assert task.run_id == run.run_id and [n.state for n in task.nodes] == ["succeeded"] * 3
    # SESSIONS.md, deferred by both threads, shows every session as it ended
    entries = {e.session_id: e.state for e in done.read("SESSIONS").data.sessions}
    assert entries == {s.session_id: "succeeded" for s in agent.summary()}
    assert done.read("SESSIONS").data.counts == {}


def _record(sid: str = "s1") -> SessionRecord:
    now = utc_now_iso()
    return SessionRecord(session_id=sid, run_id="run-1", node="n", skill="hold", target="franka_tabletop",
                         parameters={"duration_s": 0.0}, created_at=now, updated_at=now)


def _index(ws: Workspace) -> dict[str, str]:
    return {e.session_id: e.state for e in Workspace.open(ws.root).read("SESSIONS").data.sessions}


def test_deferred_sessions_md_entries_are_written_together_on_flush(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    ws.defer_index = True
    ws.submit_session(_record("s1"))
    ws.submit_session(_record("s2"))
    ws.update_session("s2", lambda r: SessionLifecycle(r).fire("time_out", reason="test"))
    assert _index(ws) == {} and ws.index_pending
    assert ws.load_session("s1").state == "pending"  # the session files are written at once
    ws.flush_index()
    assert _index(ws) == {"s1": "pending", "s2": "timed_out"} and not ws.index_pending
    counts = Workspace.open(ws.root).read("SESSIONS").data.counts
    assert counts == {"pending": 1}


def test_a_deferred_entry_never_overwrites_a_later_write_of_its_session(tmp_path):
    deferring = Workspace.create(tmp_path / "ws")
    deferring.defer_index = True
    other = Workspace.open(deferring.root)  # another writer (thread or process), not deferring
    deferring.submit_session(_record("s1"))
    deferring.submit_session(_record("s2"))
    other.update_session("s1", lambda r: SessionLifecycle(r).fire("time_out", reason="test"))
    assert _index(other) == {"s1": "timed_out"}
    deferring.flush_index()  # its "pending" of s1 is older than the stored "timed_out": dropped
    assert _index(other) == {"s1": "timed_out", "s2": "pending"}


def test_reconcile_rebuilds_a_sessions_md_left_behind_by_a_killed_writer(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    ws.submit_session(_record("s1"))
    ws.defer_index = True  # ... and the process is killed before it flushes
    ws.update_session("s1", lambda r: SessionLifecycle(r).fire("time_out", reason="test"))
    fresh = Workspace.open(ws.root)
    assert _index(fresh) == {"s1": "pending"}
    assert "stale_index" not in fresh.reconcile()  # a view younger than stale_hint_s may be a flush in progress
    assert fresh.reconcile(stale_hint_s=-1.0).get("stale_index") == 1
    assert _index(fresh) == {"s1": "timed_out"}
    assert "stale_index" not in fresh.reconcile(stale_hint_s=-1.0)  # current again


def test_two_workspace_objects_sharing_a_deferral_are_flushed_in_one_rewrite(tmp_path):
    agent = Workspace.create(tmp_path / "ws")
    agent.defer_index = True
    supervisor = Workspace.open(agent.root)
    supervisor.share_index_deferral(agent)
    agent.submit_session(_record("s1"))
    supervisor.update_session("s1", lambda r: SessionLifecycle(r).fire("time_out", reason="test"))
    agent.submit_session(_record("s2"))
    assert _index(agent) == {} and agent.index_pending and supervisor.index_pending
    writes = []
    original = agent.update
    agent.update = lambda name, fn, **kw: writes.append(name) or original(name, fn, **kw)
    agent.flush_index()
    assert writes == ["SESSIONS"] and not supervisor.index_pending
    assert _index(agent) == {"s1": "timed_out", "s2": "pending"}


def test_sharing_a_deferral_with_another_workspace_is_refused(tmp_path):
    import pytest

    from phyagentos.errors import ProtocolError

    a = Workspace.create(tmp_path / "a")
    with pytest.raises(ProtocolError, match="is not the workspace"):
        Workspace.create(tmp_path / "b").share_index_deferral(a)


def test_a_watching_supervisor_rewrites_sessions_md_off_the_hand_off_and_leaves_it_current(tmp_path, monkeypatch):
    from phyagentos.runtime.supervisor import WatchdogSupervisor

    ws = Workspace.create(tmp_path / "ws")
    writes: list[tuple[str, bool, str | None]] = []  # (thread, deferred, the session's state) per SESSIONS.md write
    original = Workspace._index_write

    def spy(self, entries, *, deferred=False):
        writes.append((threading.current_thread().name, deferred, self._states.entries().get("s1")))
        original(self, entries, deferred=deferred)

    monkeypatch.setattr(Workspace, "_index_write", spy)
    supervisor = WatchdogSupervisor(Workspace.open(ws.root))
    thread = threading.Thread(target=supervisor.serve, name="watch")
    thread.start()
    try:
        submit(ws, "s1", skill="hold", parameters={"duration_s": 0.0})
        wait_for(lambda: ws.load_session("s1").state == "awaiting_verification", timeout=120,
                 what="the runtime phase to end")
        # while the supervisor idles, SESSIONS.md shows the session as its file does (well
        # before maintenance would rebuild a stale view: reconcile's stale_hint_s)
        wait_for(lambda: _index(ws).get("s1") == "awaiting_verification", timeout=10,
                 what="SESSIONS.md current while the supervisor idles")
    finally:
        supervisor.request_stop()
        thread.join(timeout=60)
        supervisor.close()
    assert not thread.is_alive()
    mine = [w for w in writes if w[0] == "watch"]
    assert mine and all(deferred for _, deferred, _ in mine), writes
    # never while the claimed session was being preflighted and started
    assert not [w for w in mine if w[2] in ("claimed", "preflight_checking")], writes


def test_in_two_process_mode_sessions_md_is_current_once_watch_and_agent_are_idle(tmp_path):
    ws = Workspace.create(tmp_path / "ws")
    drill = Drill.start(ws, _chain(tmp_path / "chain.yaml", 3), tmp_path, supervisors=1)
    try:
        wait_for(lambda: ws.runs.load(drill.run_id).state == "finished", timeout=240, what="the run to finish")
        sessions = {r.session_id: r.state for r in ws.list_sessions(run_id=drill.run_id)}
        assert sorted(sessions.values()) == ["succeeded"] * 3
        # both processes still serve: each wrote its deferred entries before it waited
        wait_for(lambda: _index(ws) == sessions, timeout=30, what="SESSIONS.md current while watch and agent idle")
        assert drill.sups[0].poll() is None and drill.agent.poll() is None
    finally:
        codes = drill.stop()
    assert codes == [0]
    assert _index(ws) == sessions
    assert Workspace.open(ws.root).read("SESSIONS").data.counts == {}


def test_a_serving_loop_flush_reports_a_malformed_sessions_md_once_and_leaves_it_byte_for_byte(tmp_path, caplog):
    ws = Workspace.create(tmp_path / "ws")
    ws.defer_index = True
    ws.submit_session(_record("s1"))
    path = ws.path("SESSIONS")
    good = path.read_bytes()
    path.write_text(good.decode().replace("sessions: []", "sessions: [\n  - {session_id: x, node: [unclosed\n"))
    broken = path.read_bytes()
    with caplog.at_level("WARNING", logger="phyagentos.protocol.workspace"):
        assert ws.flush_index_quietly() is False
        assert ws.flush_index_quietly() is False
    warnings = [r.getMessage() for r in caplog.records if "not brought up to date" in r.getMessage()]
    assert len(warnings) == 1 and "SESSIONS.md:" in warnings[0]  # once, with the file and line
    assert path.read_bytes() == broken and ws.index_pending  # nothing overwritten, nothing lost
    path.write_bytes(good)  # repaired by hand
    assert ws.flush_index_quietly() is True and not ws.index_pending
    assert _index(ws) == {"s1": "pending"}


# -- verdict lines of LOG.md (round 9) ----------------------------------------------------


def _node_states(ws: Workspace, run_id: str) -> dict[str, str]:
    return {r.node: r.state for r in ws.list_sessions(run_id=run_id)}


def _verdict_lines(ws: Workspace) -> list[tuple[str, str]]:
    return [(e.node, e.event) for e in Workspace.open(ws.root).read("LOG").data.entries
            if e.event.startswith("verdict_")]


def test_drive_run_appends_a_verdicts_log_line_once_its_dependent_has_started(tmp_path, monkeypatch):
    from phyagentos.app.orchestrator import drive_run
    from phyagentos.runtime.supervisor import SupervisorConfig, WatchdogSupervisor

    ws = Workspace.create(tmp_path / "ws")
    agent, run = _agent(ws, _chain(tmp_path / "chain.yaml", 3))
    seen: list[tuple[str, dict[str, str]]] = []  # (node, the run's node states) per verdict line appended
    original = Workspace.append_log

    def spy(self, entry):
        if entry.event.startswith("verdict_"):
            seen.append((entry.node, _node_states(self, run.run_id)))
        original(self, entry)

    monkeypatch.setattr(Workspace, "append_log", spy)
    supervisor = WatchdogSupervisor(ws, config=SupervisorConfig(poll_interval_s=60.0))  # no quiet-interval catch-up
    try:
        drive_run(agent, supervisor)
    finally:
        supervisor.close()
    assert agent.succeeded()
    assert [node for node, _ in seen] == ["h0", "h1", "h2"], seen
    for (node, states), dependent in zip(seen, ("h1", "h2")):
        # the verdict was durable first: the dependent session was submitted, claimed and started
        assert states[node] == "succeeded", seen
        assert states.get(dependent) not in (None, "pending", "claimed", "preflight_checking"), seen
    assert _verdict_lines(ws) == [("h0", "verdict_success"), ("h1", "verdict_success"), ("h2", "verdict_success")]


def _awaiting_verification(tmp_path: Path):
    """A chain of two holds whose first session has run and awaits its verdict."""
    from phyagentos.runtime.supervisor import SupervisorConfig, WatchdogSupervisor

    ws = Workspace.create(tmp_path / "ws")
    agent, run = _agent(ws, _chain(tmp_path / "chain.yaml", 2))
    assert agent.step() == 1
    supervisor = WatchdogSupervisor(Workspace.open(ws.root), config=SupervisorConfig(poll_interval_s=0.1))
    try:
        wait_for(lambda: supervisor.step(0.1) >= 0 and _node_states(ws, run.run_id)["h0"] == "awaiting_verification",
                 timeout=120, interval=0.0, what="h0 to await its verdict")
    finally:
        supervisor.close()
    return ws, agent, run


def test_a_step_appends_its_verdicts_log_lines_after_submitting_the_dependents(tmp_path, monkeypatch):
    ws, agent, run = _awaiting_verification(tmp_path)
    seen: list[dict[str, str]] = []
    original = Workspace.append_log

    def spy(self, entry):
        seen.append(_node_states(self, run.run_id))
        original(self, entry)

    monkeypatch.setattr(Workspace, "append_log", spy)
    assert agent.step() == 2  # a verdict and a submitted session
    assert seen == [{"h0": "succeeded", "h1": "pending"}]  # not deferred without defer_task_view
    assert _verdict_lines(ws) == [("h0", "verdict_success")]


def test_a_malformed_log_md_fails_the_step_after_its_sessions_are_written_and_is_left_byte_for_byte(tmp_path):
    from phyagentos.errors import DocumentError

    ws, agent, run = _awaiting_verification(tmp_path)
    path = ws.path("LOG")
    path.write_text(path.read_text().replace("entries:", "entries: [unclosed", 1))
    broken = path.read_bytes()
    try:
        agent.step()
    except DocumentError as exc:
        assert "LOG.md" in str(exc)
    else:
        raise AssertionError("a malformed LOG.md went unreported")
    assert path.read_bytes() == broken
    # the verdict and the dependent session were written before the append failed
    assert _node_states(ws, run.run_id) == {"h0": "succeeded", "h1": "pending"}


def test_a_verdict_line_its_agent_died_before_appending_is_appended_by_the_next_agent_once(tmp_path, monkeypatch):
    from phyagentos.agent.agent_loop import load_run_graph
    from phyagentos.agent.coordinator import AgentCoordinator
    from phyagentos.app.orchestrator import skill_names

    ws, agent, run = _awaiting_verification(tmp_path)

    def dying(self, entry):
        raise KeyboardInterrupt  # the agent's process ends between the verdict and its line

    monkeypatch.setattr(Workspace, "append_log", dying)
    try:
        agent.step()
    except KeyboardInterrupt:
        pass
    else:
        raise AssertionError("the append was never attempted")
    monkeypatch.undo()
    assert _node_states(ws, run.run_id) == {"h0": "succeeded", "h1": "pending"}
    assert _verdict_lines(ws) == []
    verdict_at = next(t.at for t in ws.load_session(agent.latest_by_node()["h0"].session_id).transitions
                      if t.source == "verifying")
    for _ in range(2):  # the next agent of the run appends the owed line once, however often it steps
        successor = AgentCoordinator(ws, load_run_graph(ws, run.run_id, skills=skill_names()), run_id=run.run_id)
        successor.step()
        successor.step()
    lines = [e for e in Workspace.open(ws.root).read("LOG").data.entries if e.event.startswith("verdict_")]
    assert [(e.node, e.event, e.state, e.at) for e in lines] == [("h0", "verdict_success", "succeeded", verdict_at)]


def test_log_entries_of_a_session_are_found_in_log_md_and_in_its_archive(tmp_path):
    from phyagentos.protocol import LogEntry

    ws = Workspace.create(tmp_path / "ws")
    ws.LOG_MAX_ENTRIES = 3
    for i in range(5):
        ws.append_log(LogEntry(at=f"2026-11-23T07:00:0{i}Z", session_id=f"s{i % 2}", event=f"e{i}"))
    with (ws.log_dir / "archive-2026-11.jsonl").open("a") as archive:
        archive.write('{"session_id": "s0", "at": \n')  # torn by a crash
    assert [e.event for e in ws.log_entries_of({"s0"}, since="2026-11-01T00:00:00Z")] == ["e0", "e2", "e4"]
    assert [e.event for e in ws.log_entries_of({"s0"}, since="2026-12-01T00:00:00Z")] == ["e2", "e4"]  # LOG.md only
    assert ws.log_entries_of(set(), since="2026-11-01T00:00:00Z") == []
