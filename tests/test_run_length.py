"""A step's cost does not grow with the run's length (issue 12), pinned by behaviour.

A coordinator lists its run on every step: archived (terminal) session records are
shared between listings instead of copied, the run's archive catalogue is read from
where the last read stopped, and a frozen DAG's topological order is sorted once.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
from pathlib import Path

import networkx as nx
import pytest
import yaml

from phyagentos.agent import dag as dagmod
from phyagentos.protocol import SessionRecord, Workspace, utc_now_iso
from phyagentos.protocol.archive import SessionArchive
from phyagentos.protocol.lifecycle import SessionLifecycle


@pytest.fixture
def ws(tmp_path) -> Workspace:
    return Workspace.create(tmp_path / "ws")


def _submit(ws: Workspace, sid: str, *, run_id: str = "run-a") -> SessionRecord:
    now = utc_now_iso()
    return ws.submit_session(SessionRecord(session_id=sid, run_id=run_id, node=sid, skill="noop",
                                           target="franka_tabletop", created_at=now, updated_at=now))


def _cancel(ws: Workspace, sid: str) -> None:
    def fn(rec):
        lc = SessionLifecycle(rec)
        lc.fire("cancel")
        lc.fire("cancelled")

    ws.update_session(sid, fn)


def _replace(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)  # a new inode, as every protocol write makes


def test_shared_listings_hand_out_one_record_per_archived_session_and_read_a_replaced_file_again(ws):
    for sid in ("s1", "s2", "s3"):
        _submit(ws, sid)
    _cancel(ws, "s1")
    _cancel(ws, "s2")
    first = {r.session_id: r for r in ws.list_sessions(run_id="run-a", share_archived=True)}
    second = {r.session_id: r for r in ws.list_sessions(run_id="run-a", share_archived=True)}
    assert sorted(first) == ["s1", "s2", "s3"]
    assert first["s1"] is second["s1"] and first["s2"] is second["s2"]  # archived: shared
    assert first["s3"] is not second["s3"]  # active: read afresh
    # a listing without sharing is the caller's own: changing it changes no other listing
    own = {r.session_id: r for r in ws.list_sessions(run_id="run-a")}
    assert own["s1"] is not first["s1"] and own["s1"] == first["s1"]
    own["s1"].parameters["changed"] = True
    assert "changed" not in ws.list_sessions(run_id="run-a", share_archived=True)[0].parameters
    assert "changed" not in ws.list_sessions(run_id="run-a")[0].parameters
    # another file in the archived session's place is read again
    path = ws.find_session_path("s1")
    _replace(path, path.read_text(encoding="utf-8").replace("skill: noop", "skill: hold"))
    third = {r.session_id: r for r in ws.list_sessions(run_id="run-a", share_archived=True)}
    assert third["s1"] is not first["s1"] and third["s1"].skill == "hold"
    assert third["s2"] is first["s2"]


def test_the_run_catalogue_is_read_from_where_the_last_read_stopped_and_agrees_with_a_whole_read(ws):
    archive = SessionArchive(ws.sessions_dir)
    assert archive.run_entries("run-a") == []
    for i in range(4):
        _submit(ws, f"s{i}")
    _cancel(ws, "s0")
    _cancel(ws, "s1")
    assert [e.session_id for e in archive.run_entries("run-a")] == ["s0", "s1"]
    catalogue = next((ws.sessions_dir / "archive" / "runs").glob("*.log"))
    # An edit in place of an early line (same file, same size) is not seen by a reader
    # that parsed that line already: only what was appended since is read.
    text = catalogue.read_bytes()
    first_line = text.split(b"\n")[1]
    with open(catalogue, "r+b") as f:
        f.seek(1)
        f.write(b"x" * len(first_line))
    assert [e.session_id for e in archive.run_entries("run-a")] == ["s0", "s1"]
    assert [e.session_id for e in SessionArchive(ws.sessions_dir).run_entries("run-a")] == ["s1"]
    with open(catalogue, "r+b") as f:
        f.write(text)  # put it back
    # A line torn by a power cut is skipped, and does not swallow the line after it.
    day = text.split(b"\n")[1].split(b"/")[0]
    with open(catalogue, "ab") as f:
        f.write(b"\n" + day + b"/s2\tcancel")
    assert [e.session_id for e in archive.run_entries("run-a")] == ["s0", "s1"]
    _cancel(ws, "s3")
    assert [e.session_id for e in archive.run_entries("run-a")] == ["s0", "s1", "s3"]
    assert archive.run_entries("run-a") == SessionArchive(ws.sessions_dir).run_entries("run-a")
    # another (shorter) file in the catalogue's place is read whole
    _replace(catalogue, "\n" + text.decode("utf-8").split("\n")[1])
    assert [e.session_id for e in archive.run_entries("run-a")] == ["s0"]


def test_a_frozen_dag_is_sorted_once_and_an_unfrozen_one_follows_its_changes(monkeypatch):
    dag = nx.DiGraph()
    dag.add_nodes_from(["b", "a", "c"])
    dag.add_edge("c", "a")
    assert dagmod.topological_order(dag) == ["b", "c", "a"]
    dag.add_node("d")
    dag.add_edge("d", "b")
    assert dagmod.topological_order(dag) == ["c", "a", "d", "b"]
    frozen = nx.freeze(dag)
    order = dagmod.topological_order(frozen)
    order.append("mine")  # the caller's list: the kept order is not changed by it
    sorts = []
    real = nx.lexicographical_topological_sort
    monkeypatch.setattr(dagmod.nx, "lexicographical_topological_sort",
                        lambda *a, **kw: sorts.append(1) or real(*a, **kw))
    assert dagmod.topological_order(frozen) == ["c", "a", "d", "b"] and sorts == []
    unfrozen = nx.DiGraph(frozen)
    assert dagmod.topological_order(unfrozen) == ["c", "a", "d", "b"] and sorts == [1]


def test_records_a_run_shares_between_its_listings_are_never_modified(tmp_path, monkeypatch):
    # The coordinator's listings share archived records (read-only by contract): after a
    # whole run, every shared record is still exactly what it was when first handed out.
    from phyagentos.app.orchestrator import run_goal_graph

    handed: dict[int, tuple[SessionRecord, bytes]] = {}
    real = Workspace.list_sessions

    def recording(self, *args, **kwargs):
        records = real(self, *args, **kwargs)
        if kwargs.get("share_archived"):
            for rec in records:
                if rec.state in ("succeeded", "failed", "replanned", "timed_out", "cancelled", "rejected"):
                    handed.setdefault(id(rec), (rec, pickle.dumps(rec.model_dump(mode="json"))))
        return records

    monkeypatch.setattr(Workspace, "list_sessions", recording)
    nodes = [{"id": f"h{i}", "skill": "hold", "params": {"duration_s": 0.0},
              "accept": {"still": {"max_joint_motion_rad": 0.01}}, "depends_on": [f"h{i - 1}"] if i else []}
             for i in range(4)]
    graph = tmp_path / "holds.yaml"
    graph.write_text(yaml.safe_dump({"version": 1, "name": "holds", "defaults": {"target": "franka_tabletop"},
                                     "nodes": nodes}))
    report = run_goal_graph(graph, tmp_path / "ws", seed=0)
    assert report.succeeded
    assert len({rec.session_id for rec, _ in handed.values()}) >= 3
    for rec, at_hand_out in handed.values():
        assert pickle.dumps(rec.model_dump(mode="json")) == at_hand_out, rec.session_id


def _succeed(ws: Workspace, sid: str) -> None:
    def fn(rec):
        lc = SessionLifecycle(rec)
        for event in ("claim", "preflight", "start", "finish", "submit", "verify", "succeed"):
            lc.fire(event)

    ws.update_session(sid, fn)


def test_a_supervisor_keeps_one_catalogue_reader_for_the_dependencies_it_checks(tmp_path, ws):
    # Each hand-off asks whether the next session's dependencies succeeded; the supervisor
    # reads the run's catalogue on from where its last read stopped instead of whole.
    from phyagentos.runtime.supervisor import WatchdogSupervisor

    now = utc_now_iso()
    for sid in ("d1", "d2"):
        _submit(ws, sid)
    ws.submit_session(SessionRecord(session_id="s3", run_id="run-a", node="s3", skill="noop",
                                    target="franka_tabletop", depends_on=["d1", "d2"], created_at=now,
                                    updated_at=now))
    sup = WatchdogSupervisor(ws)
    try:
        ident = next(i for sid, _, i in ws.active_sessions("pending") if sid == "s3")
        _succeed(ws, "d1")
        assert not sup._deps_met(ident)
        reader = sup._archive
        assert reader is not None and [e.session_id for e in reader.run_entries("run-a")] == ["d1"]
        _succeed(ws, "d2")
        assert sup._deps_met(ident) and sup._archive is reader
        sup.workspace = Workspace.create(tmp_path / "other")  # another workspace: another catalogue
        assert not sup._deps_met(dataclasses.replace(ident, depends_on=("d9",)))
        assert sup._archive is not reader and sup._archive.root == sup.workspace.sessions_dir / "archive"
    finally:
        sup.close()
