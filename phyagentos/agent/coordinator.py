"""The Agent plane's loop for one run of a goal graph.

Everything it knows it reads from the workspace, so it can run in its own
process (``phyagentos agent``) or interleaved with the supervisor (``phyagentos run``):

1. verify every session of the run waiting in ``awaiting_verification``
   (SessionVerifier on the evidence bundle; the verdict is appended to the attempt);
2. on ``replan``, compile an immutable child session (``parent_session_id``
   lineage) and mark the parent ``replanned``;
3. derive node states from the sessions, block the subgraph below a failure, and
   compile pending sessions for nodes whose dependencies succeeded;
4. write TASK.md.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime

from phyagentos.protocol import LogEntry, SessionRecord, TaskDoc, TaskNode, Workspace
from phyagentos.protocol.lifecycle import SessionLifecycle, utc_now

from . import dag as dagmod
from .goal_graph import GoalGraph
from .session_compiler import SessionCompiler, new_run_id
from .verifier import SessionVerifier, load_evidence

__all__ = ["AgentCoordinator", "SessionSummary", "node_state_of"]

logger = logging.getLogger(__name__)

_RUNNING = {"pending", "claimed", "preflight_checking", "running", "finalizing", "awaiting_verification",
            "verifying", "awaiting_replan", "cancelling", "replanned"}


def node_state_of(session_state: str) -> str:
    """TASK.md node state for the state of the node's latest session."""
    if session_state in _RUNNING:
        return dagmod.RUNNING
    if session_state == "succeeded":
        return dagmod.SUCCEEDED
    if session_state == "cancelled":
        return dagmod.CANCELLED
    return dagmod.FAILED  # failed, rejected, timed_out


def _generation(session_id: str) -> int:
    return int(session_id.rsplit("-", 1)[1])


def _seconds_between(a: str | None, b: str | None) -> float | None:
    if not a or not b:
        return None
    return (datetime.fromisoformat(b) - datetime.fromisoformat(a)).total_seconds()


@dataclass(frozen=True)
class SessionSummary:
    """One row of the run summary (CLI table and ``--json``)."""

    session_id: str
    node: str
    skill: str
    target: str
    status: str
    verdict: str | None
    reason: str
    duration_s: float | None
    evidence: str | None
    parent_session_id: str | None

    def to_dict(self) -> dict:
        return dict(self.__dict__)


class AgentCoordinator:
    """Compiles, verifies and tracks one run of ``graph`` in ``workspace``.

    Args:
        workspace: the protocol workspace.
        graph: the validated goal graph.
        run_id: continue this run (default: a new run id).
        seed: base seed for the run's sessions.
        verifier: the SessionVerifier (default: predicates, 2 replans).
    """

    def __init__(self, workspace: Workspace, graph: GoalGraph, *, run_id: str | None = None, seed: int | None = 0,
                 verifier: SessionVerifier | None = None):
        self.workspace = workspace
        self.graph = graph
        self.run_id = run_id or new_run_id()
        self.dag = dagmod.to_digraph(graph)
        self.compiler = SessionCompiler(workspace, graph, self.run_id, seed=seed)
        self.verifier = verifier or SessionVerifier()

    # -- state -----------------------------------------------------------

    def sessions(self) -> list[SessionRecord]:
        """All sessions of this run, oldest first."""
        return sorted((s for s in self.workspace.list_sessions() if s.run_id == self.run_id), key=lambda s: s.created_at)

    def latest_by_node(self, sessions: list[SessionRecord] | None = None) -> dict[str, SessionRecord]:
        latest: dict[str, SessionRecord] = {}
        for s in sessions if sessions is not None else self.sessions():
            if s.node not in latest or _generation(s.session_id) > _generation(latest[s.node].session_id):
                latest[s.node] = s
        return latest

    def node_states(self, sessions: list[SessionRecord] | None = None) -> dict[str, str]:
        """Node id -> TASK.md state, with blocked nodes propagated."""
        latest = self.latest_by_node(sessions)
        states = {n: node_state_of(latest[n].state) if n in latest else dagmod.WAITING for n in self.graph.node_ids}
        return dagmod.propagate_blocked(self.dag, states)

    def done(self) -> bool:
        """True when every node is terminal (succeeded, failed, blocked or cancelled)."""
        return dagmod.is_complete(self.dag, self.node_states())

    # -- the loop --------------------------------------------------------

    def step(self) -> int:
        """Verify, replan, compile ready nodes and write TASK.md; returns actions taken."""
        actions = 0
        for rec in self.sessions():
            if rec.state == "awaiting_verification":
                actions += self._verify(rec.session_id)
        sessions = self.sessions()
        for rec in sessions:
            if rec.state == "awaiting_replan":
                actions += self._replan(rec.session_id)
        sessions = self.sessions()
        states = self.node_states(sessions)
        for node_id in dagmod.ready_nodes(self.dag, states):
            self.compiler.compile_node(self.graph.get_node(node_id))
            actions += 1
        self._write_task()
        return actions

    def _verify(self, session_id: str) -> int:
        ws = self.workspace
        with ws.session_lock(session_id):
            rec = ws.load_session(session_id)
            if rec.state != "awaiting_verification":
                return 0  # another agent got there first
            lifecycle = SessionLifecycle(rec, persist=ws.save_session)
            lifecycle.fire("verify")
        attempt = rec.attempts[-1]
        evidence = load_evidence(ws.root / attempt.evidence)
        depth = 0
        parent = rec.parent_session_id
        while parent:
            depth += 1
            parent = ws.load_session(parent).parent_session_id
        verdict = self.verifier.verify(rec, evidence, lineage_depth=depth)
        attempt.verdict = verdict
        event = {"success": "succeed", "failure": "fail", "replan": "replan"}[verdict.verdict]
        lifecycle.fire(event, reason=verdict.reason[:200])
        ws.append_log(LogEntry(at=utc_now(), session_id=rec.session_id, node=rec.node, event=f"verdict_{verdict.verdict}",
                               state=rec.state, message=verdict.reason))
        logger.info("session %s verdict %s: %s", rec.session_id, verdict.verdict, verdict.reason)
        return 1

    def _replan(self, session_id: str) -> int:
        ws = self.workspace
        rec = ws.load_session(session_id)
        child = self.compiler.compile_node(self.graph.get_node(rec.node), parent=rec, parameters=dict(rec.parameters))
        with ws.session_lock(session_id):
            rec = ws.load_session(session_id)
            rec.child_session_ids.append(child.session_id)
            SessionLifecycle(rec, persist=ws.save_session).fire("replanned", reason=f"child {child.session_id}")
        return 1

    def _write_task(self) -> None:
        sessions = self.sessions()
        states = self.node_states(sessions)
        by_node: dict[str, list[str]] = {}
        for s in sessions:
            by_node.setdefault(s.node, []).append(s.session_id)
        nodes = [
            TaskNode(id=n.id, skill=n.skill, target=n.target, depends_on=list(n.depends_on), state=states[n.id],
                     session_ids=by_node.get(n.id, []))
            for n in self.graph.nodes
        ]

        def apply(doc: TaskDoc) -> TaskDoc:
            return TaskDoc(version=doc.version, run_id=self.run_id, goal_graph=str(self.graph.path) if self.graph.path else None,
                           nodes=nodes)

        self.workspace.update("TASK", apply)

    # -- reporting -------------------------------------------------------

    def summary(self) -> list[SessionSummary]:
        """One row per session of the run, in creation order."""
        rows = []
        for s in self.sessions():
            attempt = s.attempts[-1] if s.attempts else None
            verdict = attempt.verdict if attempt else None
            reason = verdict.reason if verdict else ("; ".join(f"{r.code} ({r.field}): expected {r.expected}, found {r.found}"
                                                               for r in s.rejection) or
                                                    (attempt.error.message if attempt and attempt.error else ""))
            rows.append(SessionSummary(
                session_id=s.session_id, node=s.node, skill=s.skill, target=s.target, status=s.state,
                verdict=verdict.verdict if verdict else None, reason=reason,
                duration_s=_seconds_between(attempt.started_at, attempt.ended_at) if attempt else None,
                evidence=attempt.evidence if attempt else None, parent_session_id=s.parent_session_id,
            ))
        return rows

    def succeeded(self) -> bool:
        """True when every node's latest session succeeded."""
        return all(state == dagmod.SUCCEEDED for state in self.node_states().values())
