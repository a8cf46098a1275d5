"""The read-only view of one run of an :class:`~phyagentos.agent.coordinator.AgentCoordinator`:
its sessions, each node's latest session and TASK.md state, the lineage of a session,
what finished sessions observed of an object, the targets re-targets moved nodes to, the
upstream nodes re-opened (re-picks), and the run summary. Everything is derived from the
session files of the workspace (mixed into the coordinator as :class:`RunView`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import datetime
from typing import TYPE_CHECKING, Any, Mapping

import networkx as nx

from phyagentos.errors import VerifierError
from phyagentos.protocol import SessionRecord

from . import dag as dagmod
from .memory.observed import ObservedObject, observe_object
from .recovery import ACQUIRING_SKILLS

if TYPE_CHECKING:
    from phyagentos.protocol import Workspace

    from .goal_graph import GoalGraph

# the coordinator's log, as before it was split into mix-ins
logger = logging.getLogger("phyagentos.agent.coordinator")

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
    cause: str | None = None  # diagnosed cause of an unsuccessful verdict
    strategy: str | None = None  # recovery strategy this (child) session ran with
    memory: tuple[str, ...] = ()  # ids of memory items that set its parameters

    def to_dict(self) -> dict:
        return dict(self.__dict__)


class RunView:
    """Sessions, node states, lineage, observations, re-openings and the run summary.

    Mixed into :class:`~phyagentos.agent.coordinator.AgentCoordinator`.
    """

    workspace: Workspace
    graph: GoalGraph
    run_id: str
    dag: nx.DiGraph

    # -- state -----------------------------------------------------------

    def sessions(self) -> list[SessionRecord]:
        """All sessions of this run, oldest first (active ones via the state index, finished
        ones via the run's archive catalogue: the cost does not grow with other runs).

        Active sessions are read afresh; the records of archived (terminal) sessions are
        the workspace's own, shared by every listing (``share_archived``): read them, never
        modify them (load a session to change it). A step lists the run, so copying every
        finished session on every step made a long run's hand-offs slower the longer it ran.
        """
        return self.workspace.list_sessions(run_id=self.run_id, share_archived=True)

    def latest_by_node(self, sessions: list[SessionRecord] | None = None) -> dict[str, SessionRecord]:
        latest: dict[str, SessionRecord] = {}
        for s in sessions if sessions is not None else self.sessions():
            if s.node not in latest or _generation(s.session_id) > _generation(latest[s.node].session_id):
                latest[s.node] = s
        return latest

    def node_states(self, sessions: list[SessionRecord] | None = None) -> dict[str, str]:
        """Node id -> TASK.md state, with blocked nodes propagated. A node waiting for a
        re-opened upstream node is blocked when that node ends unsuccessfully."""
        latest = self.latest_by_node(sessions)
        states = {n: node_state_of(latest[n].state) if n in latest else dagmod.WAITING for n in self.graph.node_ids}
        for node, (rec, upstream) in self._awaiting_reopen(latest).items():
            if states.get(upstream) in dagmod.BLOCKING_STATES:
                states[node] = dagmod.BLOCKED
        return dagmod.propagate_blocked(self.dag, states)

    def done(self, sessions: list[SessionRecord] | None = None) -> bool:
        """True when every node is terminal (succeeded, failed, blocked or cancelled);
        ``sessions`` as :meth:`node_states` takes them (default: listed now)."""
        return dagmod.is_complete(self.dag, self.node_states(sessions))

    def succeeded(self) -> bool:
        """True when every node's latest session succeeded."""
        return all(state == dagmod.SUCCEEDED for state in self.node_states().values())

    def lineage(self, rec: SessionRecord) -> list[SessionRecord]:
        """``rec``'s ancestors along ``parent_session_id``, oldest first."""
        chain: list[SessionRecord] = []
        parent = rec.parent_session_id
        while parent:
            chain.append(self.workspace.load_session(parent))
            parent = chain[-1].parent_session_id
        return chain[::-1]

    def observed(self, obj: Any, sessions: list[SessionRecord] | None = None) -> ObservedObject | None:
        """What this run's finished sessions observed of object ``obj`` (perceived geometry,
        mass estimated from the wrist load, slips), from their evidence bundles."""
        if not isinstance(obj, str):
            return None
        bundles = []
        for s in sessions if sessions is not None else self.sessions():
            for attempt in s.attempts:
                if attempt.evidence and (self.workspace.root / attempt.evidence / "bundle.yaml").is_file():
                    try:
                        bundles.append(self._evidence(self.workspace.root / attempt.evidence))
                    except VerifierError as exc:  # an unreadable bundle contributes nothing, never stops the run
                        logger.warning("evidence %s unreadable for observations: %s", attempt.evidence, exc)
        return observe_object(bundles, obj)

    def world_target(self, node_id: str, latest: Mapping[str, SessionRecord]) -> str | None:
        """The target a ready node must run on when a re-target moved its world: the target of the
        latest sessions of its DAG ancestors when a re-target revision put one of them on another
        target than its node's (each target is its own world: the node finds what its upstream
        nodes did only there); ``None``: the node's own target."""
        moved = set()
        for up in nx.ancestors(self.dag, node_id):
            rec = latest.get(up)
            if rec is not None and rec.target != self.graph.get_node(up).target:
                moved.add(rec.target)
        if len(moved) > 1:
            logger.warning("node %s: upstream nodes were moved to several targets %s; it keeps its own", node_id,
                           sorted(moved))
            return None
        return next(iter(moved), None)


    # -- re-opening upstream nodes -----------------------------------------

    def upstream_acquirer(self, session: SessionRecord) -> str | None:
        """The nearest DAG ancestor of ``session``'s node that acquires its ``object``
        (a node of an :data:`ACQUIRING_SKILLS` skill with the same object), or ``None``."""
        obj = session.parameters.get("object")
        if not isinstance(obj, str) or session.node not in self.dag:
            return None
        ancestors = nx.ancestors(self.dag, session.node)
        order = [n for n in reversed(dagmod.topological_order(self.dag)) if n in ancestors]
        for n in order:
            node = self.graph.get_node(n)
            if node.skill in ACQUIRING_SKILLS and node.params.get("object") == obj:
                return n
        return None

    @staticmethod
    def _revision(rec: SessionRecord):
        verdict = rec.attempts[-1].verdict if rec.attempts else None
        return verdict.revision if verdict is not None else None

    def _awaiting_reopen(self, latest: dict[str, SessionRecord]) -> dict[str, tuple[SessionRecord, str]]:
        """Node -> (its replanned session, the upstream node it re-opened) for nodes whose
        latest session re-opened an upstream node and has no child yet."""
        out = {}
        for node, rec in latest.items():
            rev = self._revision(rec)
            if rec.state == "replanned" and rev is not None and rev.reopen:
                out[node] = (rec, rev.reopen)
        return out

    def reopen_edges(self, sessions: list[SessionRecord] | None = None) -> list[tuple[str, str, str, str]]:
        """Recorded re-openings ``(upstream node, node, failed session, re-pick session)``;
        also set as ``reopened_by`` on the DAG edge upstream -> node."""
        edges = []
        for rec in sessions if sessions is not None else self.sessions():
            rev = self._revision(rec)
            if rev is not None and rev.reopen and rec.child_session_ids:
                edges.append((rev.reopen, rec.node, rec.session_id, rec.child_session_ids[0]))
        for up, node, failed, repick in edges:
            if self.dag.has_edge(up, node):
                tags = self.dag.edges[up, node].setdefault("reopened_by", [])
                if (failed, repick) not in tags:
                    tags.append((failed, repick))
        return edges


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
                cause=verdict.diagnosis.cause if verdict and verdict.diagnosis else None,
                strategy=s.recovery.strategy if s.recovery else None,
                memory=tuple(i.id for i in s.context.items if i.applied) if s.context else (),
            ))
        return rows
