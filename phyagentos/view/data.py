"""What the view shows, read from the workspace through the protocol's readers.

Every function returns plain data; a malformed document never breaks the page: the
panel that needs it carries the error (the :class:`~phyagentos.errors.DocumentError`
message names the file and line) and every other panel still renders. Nothing here
writes to the workspace.
"""

from __future__ import annotations

import logging
import os
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import networkx as nx
import yaml

from phyagentos.agent import dag as dagmod
from phyagentos.agent.coordinator import node_state_of
from phyagentos.errors import DocumentError, PhyAgentOSError, ProtocolError, ViewError
from phyagentos.protocol import SessionRecord, Workspace, fold_signals
from phyagentos.protocol.archive import SessionArchive
from phyagentos.untrusted import loads_json, read_regular
from phyagentos.yamlsource import read_yaml

from .security import evidence_dir

__all__ = ["Panel", "panel", "signals_in_force", "held_state", "overview", "runs", "runs_page", "RunsCache",
           "RUNS_PER_PAGE", "run_sessions", "run_graph", "session_detail", "tree_status", "memory",
           "SESSION_LINK_PATTERN"]

logger = logging.getLogger(__name__)

#: Session ids and run ids as they appear in provenance lists and evidence paths.
SESSION_LINK_PATTERN = r"[A-Za-z0-9][A-Za-z0-9_.-]{0,127}"


@dataclass(frozen=True)
class Panel:
    """A panel's data, or the error that kept it from being read."""

    data: Any = None
    error: str | None = None


def panel(fn: Callable[[], Any]) -> Panel:
    """Run ``fn``; a protocol error (malformed document, missing file) becomes the panel's error."""
    try:
        return Panel(data=fn())
    except (PhyAgentOSError, OSError, yaml.YAMLError, ValueError) as exc:
        logger.info("view panel error: %s", exc)
        return Panel(error=str(exc))


#: Session states a session waits in until a supervisor claims it: a pause or an e-stop
#: in force holds it there (supervisors claim nothing), so the view says so.
WAITING_TO_BE_CLAIMED = frozenset({"pending"})


def signals_in_force(ws: Workspace) -> dict[str, Any]:
    """``{paused, estopped, estop_reason, estop_by, estop_at, pause_by, pause_at}`` from RUNTIME_SIGNAL.md.

    A pause stops dispatch (supervisors claim no new session; running sessions go on);
    an e-stop halts motion and cancels running sessions.
    """
    s = fold_signals(ws.read("RUNTIME_SIGNAL").data.signals)
    return {"paused": s.paused, "estopped": s.estopped,
            "estop_reason": s.estop.reason if s.estop else "",
            "estop_by": s.estop.issued_by if s.estop else "", "estop_at": str(s.estop.issued_at) if s.estop else "",
            "pause_by": s.pause_signal.issued_by if s.paused and s.pause_signal else "",
            "pause_at": str(s.pause_signal.issued_at) if s.paused and s.pause_signal else ""}


def held_state(state: str, signals: dict[str, Any]) -> str | None:
    """``held_by_estop`` / ``paused`` for a session in ``state`` that a signal keeps from being claimed, else None."""
    if state not in WAITING_TO_BE_CLAIMED:
        return None
    if signals["estopped"]:
        return "held_by_estop"
    if signals["paused"]:
        return "paused"
    return None


def overview(ws: Workspace) -> dict[str, Any]:
    """Signals in force and active sessions (from ``sessions/.index``)."""
    signals = signals_in_force(ws)
    active = [{"session_id": sid, "state": state, "held": held_state(state, signals), "run_id": ident.run_id,
               "node": ident.node, "skill": ident.skill, "target": ident.target}
              for sid, state, ident in ws.active_sessions()]
    return {**signals, "signals": signals, "active": active}


class RunsCache:
    """Rows of ``runs/<id>/RUN.md`` kept between requests, re-read only when a file's
    ``(mtime_ns, size)`` changed: listing 1,000 runs costs a ``scandir`` and a ``stat`` each."""

    def __init__(self) -> None:
        self._rows: dict[str, tuple[tuple[int, int], dict[str, Any]]] = {}
        self.reads = 0
        self._lock = threading.Lock()

    def rows(self, ws: Workspace) -> list[dict[str, Any]]:
        """Every run's row, newest first (see :func:`runs`)."""
        with self._lock:
            return self._rows_locked(ws)

    def _rows_locked(self, ws: Workspace) -> list[dict[str, Any]]:
        out = []
        directory = ws.root / "runs"
        if not directory.is_dir():
            return out
        seen = set()
        for entry in os.scandir(directory):
            if entry.name.startswith(".") or not entry.is_dir():
                continue
            seen.add(entry.name)
            try:
                st = os.stat(os.path.join(entry.path, "RUN.md"))
                key = (st.st_mtime_ns, st.st_size)
            except OSError:
                key = (0, -1)
            hit = self._rows.get(entry.name)
            if hit is not None and hit[0] == key:
                out.append(hit[1])
                continue
            self.reads += 1
            row = _run_row(ws, entry.name)
            self._rows[entry.name] = (key, row)
            out.append(row)
        for gone in set(self._rows) - seen:
            del self._rows[gone]
        out.sort(key=lambda r: (r["submitted_at"], r["run_id"]), reverse=True)
        return out


def _run_row(ws: Workspace, name: str) -> dict[str, Any]:
    try:
        rec = ws.runs.load(name)
        return {"run_id": rec.run_id, "goal_graph": rec.goal_graph, "state": rec.state,
                "succeeded": rec.succeeded, "submitted_at": str(rec.submitted_at), "error": None}
    except PhyAgentOSError as exc:
        return {"run_id": name, "goal_graph": "", "state": "?", "succeeded": None, "submitted_at": "",
                "error": str(exc)}


def runs(ws: Workspace, cache: RunsCache | None = None) -> list[dict[str, Any]]:
    """Every run of the workspace (``runs/<id>/RUN.md``), newest first; a malformed RUN.md is a row with its error."""
    return (cache or RunsCache()).rows(ws)


#: Runs per page of the index.
RUNS_PER_PAGE = 50


def runs_page(ws: Workspace, page: int, *, cache: RunsCache | None = None,
              per_page: int = RUNS_PER_PAGE) -> dict[str, Any]:
    """Page ``page`` (1-based, clamped) of :func:`runs`: ``{rows, page, pages, total, per_page}``."""
    rows = runs(ws, cache)
    pages = max(1, -(-len(rows) // per_page))
    page = min(max(1, page), pages)
    return {"rows": rows[(page - 1) * per_page: page * per_page], "page": page, "pages": pages,
            "total": len(rows), "per_page": per_page}


def _graph_nodes(ws: Workspace, run_id: str) -> list[dict[str, Any]]:
    """Nodes of the run's submitted goal graph (id, skill, depends_on), in file order."""
    path = ws.runs.graph_path(run_id)
    raw = _yaml_file(path, ws.root)
    nodes = raw.get("nodes", []) if isinstance(raw, dict) else []
    return [{"id": str(n.get("id")), "skill": str(n.get("skill", "")), "depends_on": [str(d) for d in n.get("depends_on") or []]}
            for n in nodes if isinstance(n, dict) and n.get("id") is not None]


def run_sessions(ws: Workspace, run_id: str) -> list[SessionRecord]:
    """The run's sessions, oldest first, read without taking a lock or writing anything.

    ``Workspace.list_sessions`` repairs stale state hints under the session lock; a viewer
    must never contend with supervisors for locks or write, so this reads the active
    sessions named by ``sessions/.index`` and the run's archive catalogue only (a session
    that moved between the two reads is picked up by the next refresh).

    Raises:
        DocumentError: a session file is malformed.
    """
    by_id: dict[str, SessionRecord] = {}
    for sid, _, _ in ws.active_sessions(run_id=run_id):
        try:
            by_id[sid] = ws.load_session(sid)
        except DocumentError:
            raise
        except ProtocolError:
            continue  # submitted this instant, or archived meanwhile
    for entry in SessionArchive(ws.sessions_dir).run_entries(run_id):
        if entry.session_id not in by_id:
            try:
                by_id[entry.session_id] = ws.load_session(entry.session_id)
            except DocumentError:
                raise
            except ProtocolError:
                continue
    return sorted(by_id.values(), key=lambda r: (str(r.created_at), r.session_id))


def run_graph(ws: Workspace, run_id: str) -> dict[str, Any]:
    """The run's DAG: nodes (state, skill, dependencies) with their sessions and replan lineage.

    Node states are those the Agent plane computes (latest session's state, ``blocked``
    propagated along dependencies; ``waiting`` before a node has a session).
    """
    sessions = run_sessions(ws, run_id)
    nodes = _graph_nodes(ws, run_id)
    known = {n["id"] for n in nodes}
    for s in sessions:
        if s.node not in known:
            nodes.append({"id": s.node, "skill": s.skill, "depends_on": list(s.depends_on)})
            known.add(s.node)
    by_node: dict[str, list[SessionRecord]] = {}
    for s in sessions:
        by_node.setdefault(s.node, []).append(s)
    dag = nx.DiGraph()
    dag.add_nodes_from(known)
    dag.add_edges_from((d, n["id"]) for n in nodes for d in n["depends_on"] if d in known)
    raw = {n: node_state_of(by_node[n][-1].state) if n in by_node else dagmod.WAITING for n in known}
    states = dagmod.propagate_blocked(dag, raw)
    signals = signals_in_force(ws)
    for n in nodes:
        n["state"] = states[n["id"]]
        n["sessions"] = [_session_box(s) for s in by_node.get(n["id"], [])]
        # The Agent plane calls a node with a submitted session "running"; while a pause or an
        # e-stop keeps that session from being claimed, nothing runs: show what holds it.
        latest = by_node.get(n["id"], [None])[-1]
        held = held_state(latest.state, signals) if latest is not None and n["state"] == dagmod.RUNNING else None
        if held:
            n["agent_state"], n["state"] = n["state"], held
    return {"run_id": run_id, "nodes": nodes, "signals": signals}


def _session_box(s: SessionRecord) -> dict[str, Any]:
    verdict = s.attempts[-1].verdict if s.attempts else None
    return {"session_id": s.session_id, "state": s.state, "parent": s.parent_session_id,
            "verdict": verdict.verdict if verdict else None,
            "cause": verdict.diagnosis.cause if verdict and verdict.diagnosis else None,
            "strategy": s.recovery.strategy if s.recovery else None}


def _yaml_file(path: Path, root: Path) -> Any:
    """The YAML file ``path`` (None when absent), read only if it resolves inside ``root``
    and is a regular file (a link out of the workspace or a FIFO is this panel's error)."""
    try:
        return read_yaml(path, error=ViewError, root=root)
    except FileNotFoundError:
        return None


def session_detail(ws: Workspace, session_id: str) -> dict[str, Any]:
    """One session: its record (as JSON data) plus what its evidence bundle holds.

    Raises:
        ProtocolError: unknown or invalid session id; DocumentError: malformed session file.
    """
    rec = ws.load_session(session_id)
    evidence_rel = f"evidence/{session_id}"
    directory = evidence_dir(ws.root, session_id)  # ViewError: a link out of the workspace
    files = sorted(p.name for p in directory.iterdir() if p.is_file() and not p.name.startswith(".")) \
        if directory.is_dir() else []
    signals = signals_in_force(ws)
    out: dict[str, Any] = {"record": rec.model_dump(mode="json"), "evidence_dir": evidence_rel, "files": files,
                           "signals": signals, "held": held_state(rec.state, signals)}
    out["bundle"] = panel(lambda: _yaml_file(directory / "bundle.yaml", ws.root))
    out["events"] = panel(lambda: _yaml_file(directory / "events.yaml", ws.root) or [])
    out["perception"] = panel(lambda: _perception(ws, rec, directory))
    return out


def _perception(ws: Workspace, rec: SessionRecord, directory: Path) -> dict[str, Any]:
    """Entities the session saw: ENVIRONMENT.md while it is this session's, else the terminal snapshot."""
    env = ws.read("ENVIRONMENT").data
    if env.session_id == rec.session_id and env.entities:
        return {"source": "ENVIRONMENT.md", "sim_time_s": env.sim_time_s,
                "entities": [e.model_dump(mode="json") for e in env.entities]}
    for name in ("terminal.yaml", "initial.yaml"):
        snap = _yaml_file(directory / name, ws.root)
        if isinstance(snap, dict) and snap.get("entities"):
            return {"source": f"{directory.name}/{name}", "sim_time_s": snap.get("sim_time_s"),
                    "entities": snap["entities"]}
    return {"source": None, "entities": []}


#: Largest ``tree.json`` the view reads (bytes): a published tree is a few kilobytes.
MAX_TREE_JSON_BYTES = 8 * 1024 * 1024
#: Deepest nesting of ``tree.json`` (a behaviour tree's depth is a handful of levels).
MAX_TREE_JSON_DEPTH = 200


def tree_status(ws: Workspace, session_id: str) -> dict[str, Any] | None:
    """The live ``evidence/<session>/tree.json`` the runner publishes, or None before the first tick.

    Raises:
        ViewError: the evidence directory resolves outside the workspace.
        OSError: ``tree.json`` resolves outside the workspace or is not a regular file
            (:mod:`phyagentos.untrusted`).
        ValueError: larger than :data:`MAX_TREE_JSON_BYTES`, deeper than
            :data:`MAX_TREE_JSON_DEPTH` or not JSON.
    """
    path = evidence_dir(ws.root, session_id) / "tree.json"
    try:
        raw = read_regular(path, limit=MAX_TREE_JSON_BYTES, root=ws.root)
    except FileNotFoundError:
        return None
    return loads_json(raw, max_bytes=MAX_TREE_JSON_BYTES, max_depth=MAX_TREE_JSON_DEPTH)


def memory(ws: Workspace) -> dict[str, Panel]:
    """LESSONS.md (lessons and candidates), KNOWLEDGE.md and SKILL.md, each its own panel."""
    return {
        "lessons": panel(lambda: ws.read("LESSONS").data.model_dump(mode="json")),
        "knowledge": panel(lambda: ws.read("KNOWLEDGE").data.model_dump(mode="json")),
        "skills": panel(lambda: ws.read("SKILL").data.model_dump(mode="json")),
    }
