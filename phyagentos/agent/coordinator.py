"""The Agent plane's loop for one run of a goal graph.

Everything it knows it reads from the workspace, so it can run in its own
process (``phyagentos agent``) or interleaved with the supervisor (``phyagentos run``):

1. verify every session of the run waiting in ``awaiting_verification``
   (SessionVerifier on the evidence bundle; the verdict, with its diagnosis and for a
   replan the proposed revision, is appended to the attempt), apply the evidence
   retention policy (images of successes are dropped unless kept on purpose), and
   consolidate the verdict into memory (lessons, knowledge, promoted procedures);
2. on ``replan``, compile an immutable child session (``parent_session_id``
   lineage, the revision's parameters, ``recovery`` recording why) and mark the
   parent ``replanned``; the correction it tries becomes a lesson *candidate*;
3. derive node states from the sessions, block the subgraph below a failure, and
   compile pending sessions for nodes whose dependencies succeeded, each with the
   memory the ContextBuilder retrieves for it (recorded in the session's ``context``);
4. write TASK.md.

Three recoveries change more than parameters (:mod:`phyagentos.agent.recovery`,
:mod:`phyagentos.agent.retarget`):

- *another view* (``Revision.skill == "observe"``): the child session only looks again;
  the criteria are then judged on the acting session's evidence with the child's
  terminal snapshot as the terminal state (the session that acted is judged, with a
  better look at its result);
- *re-pick upstream* (``Revision.reopen``): a place that found nothing in the hand
  re-opens the upstream node that acquires the object. The coordinator compiles a new
  session of that node (parent: its latest session, ``recovery`` naming the cause),
  records the re-opening on the DAG edge (``reopened_by`` on the edge upstream ->
  node, and the new session id among the failed session's ``child_session_ids``), and
  compiles the node's child once the re-pick succeeded; if it fails, the node is
  blocked;
- *re-target* (``Revision.target``): the child runs the same node, skill and criteria on
  the other target the selector chose; its later children, the nodes downstream of it and
  any re-opened upstream node follow it there (:meth:`AgentCoordinator.world_target`: each
  target is its own world).
"""

from __future__ import annotations

import logging
import os
import socket
from collections import Counter, OrderedDict
from dataclasses import dataclass, replace
from datetime import datetime
from typing import Any, Callable, Mapping

import networkx as nx

from phyagentos.errors import PhyAgentOSError, VerifierError
from phyagentos.protocol import (
    LogEntry,
    SessionRecord,
    TaskDoc,
    TaskNode,
    Workspace,
    file_identity,
    is_expired,
    new_lease,
)
from phyagentos.protocol.evidence_markers import PRUNED_MARKER, images_pending, wait_for_images
from phyagentos.protocol.lifecycle import SessionLifecycle, utc_now
from phyagentos.protocol.schemas import TransitionRecord

from . import dag as dagmod
from .declared import declared_scene
from .goal_graph import GoalGraph
from .memory import ContextBuilder, KnowledgeBase, LessonBook, PromotionPolicy, promote
from .memory.conditions import Conditions
from .memory.deaths import SURVIVAL_KEYS
from .memory.game import is_game_skill, learn_game_session
from .memory.observed import ObservedObject, observe_object
from .memory.promotion import initial_state_fingerprint
from .model_calls import planner_calls, trace_calls, with_calls
from .recovery import ACQUIRING_SKILLS, SITUATIONAL
from .session_compiler import SessionCompiler, new_run_id
from .verifier import EvidenceBundle, SessionVerifier, load_evidence

__all__ = ["AgentCoordinator", "SessionSummary", "node_state_of"]

logger = logging.getLogger(__name__)

#: Evidence bundles an AgentCoordinator keeps parsed (:meth:`AgentCoordinator._evidence`).
_BUNDLES_KEPT = 64

# A verification holds a lease like a supervisor's claim, so one whose agent process
# died is taken up again by the next agent instead of staying ``verifying`` forever.
_AGENT_ID = f"agent:{socket.gethostname()}:{os.getpid()}"
_VERIFY_LEASE_S = 60.0
#: lifecycle event of a verdict (from ``verifying``) -> the verdict
_VERDICT_OF_EVENT = {"succeed": "success", "fail": "failure", "replan": "replan"}
_EVENT_OF_VERDICT = {verdict: event for event, verdict in _VERDICT_OF_EVENT.items()}

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


def _descends(session_id: str | None, ancestor: str, parents: Mapping[str, str | None]) -> bool:
    """``session_id`` is ``ancestor`` or one of its descendants along ``parent_session_id``."""
    seen = set()
    while session_id is not None and session_id not in seen:
        if session_id == ancestor:
            return True
        seen.add(session_id)
        session_id = parents.get(session_id)
    return False


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


class AgentCoordinator:
    """Compiles, verifies and tracks one run of ``graph`` in ``workspace``.

    Args:
        workspace: the protocol workspace.
        graph: the validated goal graph.
        run_id: continue this run (default: a new run id).
        seed: base seed for the run's sessions.
        verifier: the SessionVerifier (default: predicates, 2 replans).
        evaluation: benchmark evaluation configuration recorded in every session.
        use_memory: retrieve lessons, knowledge and procedures for new sessions
            (``False``: run as if memory were empty; conditions are still recorded).
        consolidate: write verdicts into memory (LESSONS.md, KNOWLEDGE.md, SKILL.md);
            ``False`` keeps memory frozen (a measurement).
        keep_success_images: keep the RGB images of sessions whose verdict is success
            (failures always keep theirs).
        promotion: thresholds for promoting knowledge to SKILL.md.
    """

    #: verdicts' LOG.md lines not yet appended (see :meth:`step`); a list once constructed
    _owed_log: list[LogEntry] | tuple = ()

    def __init__(self, workspace: Workspace, graph: GoalGraph, *, run_id: str | None = None, seed: int | None = 0,
                 verifier: SessionVerifier | None = None, evaluation: dict | None = None, use_memory: bool = True,
                 consolidate: bool = True, keep_success_images: bool = False,
                 promotion: PromotionPolicy | None = None):
        self.workspace = workspace
        self.graph = graph
        self.run_id = run_id or new_run_id()
        # frozen: the run's DAG never changes shape (edge attributes such as
        # ``reopened_by`` still may), so its topological order is sorted once
        self.dag = nx.freeze(dagmod.to_digraph(graph))
        self.compiler = SessionCompiler(workspace, graph, self.run_id, seed=seed, evaluation=evaluation)
        self.verifier = verifier or SessionVerifier()
        self.verifier.set_upstream(self.upstream_acquirer)
        self.context_builder = ContextBuilder(workspace, use_memory=use_memory, trials=consolidate)
        self.consolidate = consolidate
        self.keep_success_images = keep_success_images
        self.promotion = promotion or PromotionPolicy()
        #: called right after each session :meth:`step` submits (e.g. to wake a supervisor)
        self.on_submit: Callable[[], None] | None = None
        #: the run's sessions as the last :meth:`step` left them (for its caller's report)
        self.last_sessions: list[SessionRecord] | None = None
        #: ``True``: a step that submitted sessions leaves TASK.md (a view) to :meth:`write_task`,
        #: which its caller runs once the hand-off is over (``drive_run``: once no session of the
        #: run waits to be claimed or started), so that the step's re-listing and the view's
        #: rendering do not compete with the supervisor's claim for the interpreter
        self.defer_task_view = False
        #: whether TASK.md lags behind the last step (a deferred write is due)
        self.task_view_stale = False
        #: verdicts' LOG.md lines not yet appended (see :meth:`step`)
        self._owed_log: list[LogEntry] = []
        #: whether the first step looked for verdict lines an earlier agent of this run owed
        self._lines_checked = False
        #: evidence bundles read for verdicts and observations, by directory (see :meth:`_evidence`)
        self._bundles: OrderedDict[str, tuple[tuple[int, int, int], EvidenceBundle]] = OrderedDict()

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

    def _resume_after_reopen(self, sessions: list[SessionRecord]) -> int:
        """Compile the child of every node whose re-opened upstream node has succeeded again."""
        actions = 0
        latest = self.latest_by_node(sessions)
        parents = {s.session_id: s.parent_session_id for s in sessions}
        for node_id, (rec, upstream) in self._awaiting_reopen(latest).items():
            up = latest.get(upstream)
            repick = rec.child_session_ids[0] if rec.child_session_ids else None
            # the re-pick itself, or a child the verifier made of it (a re-pick that replanned)
            if up is None or repick is None or up.state != "succeeded" or not _descends(up.session_id, repick, parents):
                continue
            rev = self._revision(rec)
            resume = rev.model_copy(update={"rationale": f"{rev.rationale}; upstream {repick} succeeded"})
            self.compiler.compile_node(self.graph.get_node(node_id), parent=rec, parameters=dict(rec.parameters),
                                       limits=rec.limits.model_dump(), context=rec.context, recovery=resume,
                                       target=rec.target)
            actions += 1
        return actions

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

    def done(self, sessions: list[SessionRecord] | None = None) -> bool:
        """True when every node is terminal (succeeded, failed, blocked or cancelled);
        ``sessions`` as :meth:`node_states` takes them (default: listed now)."""
        return dagmod.is_complete(self.dag, self.node_states(sessions))

    # -- the loop --------------------------------------------------------

    def step(self) -> int:
        """Verify, replan, compile ready nodes and write TASK.md; returns actions taken.

        The run's sessions are listed again only after a replan or a resumed node (a
        verdict patches the listing with the record it wrote); ``on_submit``, if set, is
        called as soon as a ready node's session is submitted (``drive_run`` wakes the
        supervisor with it, before TASK.md is rewritten).

        The verdicts' LOG.md lines are appended after the ready nodes are submitted:
        the verdict in the session file is what a dependent session waits for, and the
        log line only records it. With :attr:`defer_task_view`,
        a step that submitted leaves them to :meth:`write_task`, with TASK.md. Each line
        carries its verdict's time (``at``); another process's line may precede it. A
        coordinator's first step also appends the lines an earlier agent of the run died
        owing (:meth:`_verdict_lines_owed`): a killed agent's lines are appended by the
        run's next agent (an agent that starts on a run another live agent still serves
        may append a line twice, never lose one).

        Raises:
            DocumentError: LOG.md or another protocol document is malformed (a LOG.md
                append fails after this step's session writes; nothing is lost).
        """
        try:
            actions = self._step()
        except BaseException:
            self.append_owed_log(quiet=True)
            raise
        if not (self.defer_task_view and self.task_view_stale):
            self.append_owed_log()
        return actions

    def append_owed_log(self, *, quiet: bool = False) -> None:
        """Append the verdicts' LOG.md lines that steps owe (see :meth:`step`), oldest
        first. Every line is tried; the first failure is raised afterwards (``quiet``:
        only logged, e.g. while another exception ends the run).

        Raises:
            DocumentError: LOG.md is malformed (LOG.md is left as it was).
            ProtocolError: LOG.md is missing.
            OSError: LOG.md or its archive cannot be written.
        """
        owed, self._owed_log = list(self._owed_log), []
        first: Exception | None = None
        for entry in owed:
            try:
                self.workspace.append_log(entry)
            except (PhyAgentOSError, OSError) as exc:
                logger.error("could not append the verdict of session %s to LOG.md: %s", entry.session_id, exc)
                first = first or exc
        if first is not None and not quiet:
            raise first

    def _verdict_lines_owed(self, sessions: list[SessionRecord]) -> list[LogEntry]:
        """The LOG.md lines of this run's verdicts that are in no log (LOG.md or its
        archive), oldest first: an agent killed between a verdict and its line (see
        :meth:`step`) owes them, and the coordinator that takes the run over appends
        them with its first step, each with its verdict's time, state and reason (from
        the session file). Lines are matched by session and event, counted."""
        verdicts: list[tuple[SessionRecord, TransitionRecord, str]] = [
            (rec, t, f"verdict_{_VERDICT_OF_EVENT[name]}") for rec in sessions for t in rec.transitions
            if t.source == "verifying" and (name := t.event.split(":", 1)[0]) in _VERDICT_OF_EVENT]
        if not verdicts:
            return []
        try:
            logged = Counter((e.session_id, e.event) for e in self.workspace.log_entries_of(
                {rec.session_id for rec, _, _ in verdicts}, since=min(t.at for _, t, _ in verdicts)))
        except (PhyAgentOSError, OSError) as exc:  # the next append reports it (and writes nothing)
            logger.warning("run %s: LOG.md not checked for owed verdict lines: %s", self.run_id, exc)
            return []
        owed: list[LogEntry] = []
        for rec, t, event in sorted(verdicts, key=lambda v: v[1].at):
            if logged[(rec.session_id, event)] > 0:
                logged[(rec.session_id, event)] -= 1
                continue
            verdict = next((a.verdict for a in reversed(rec.attempts) if a.verdict is not None), None)
            owed.append(LogEntry(at=t.at, session_id=rec.session_id, node=rec.node, event=event, state=t.dest,
                                 message=verdict.reason if verdict is not None else ""))
        if owed:
            logger.warning("run %s: appending %d verdict line(s) to LOG.md that an earlier agent owed: %s",
                           self.run_id, len(owed), ", ".join(e.session_id for e in owed))
        return owed

    def _step(self) -> int:
        actions = 0
        sessions = self.sessions()
        if not self._lines_checked:
            self._owed_log[:0] = self._verdict_lines_owed(sessions)
            self._lines_checked = True
        verified: dict[str, SessionRecord] = {}
        for rec in sessions:
            # a verification whose agent died (its lease expired) is taken up again
            if rec.state == "awaiting_verification" or (rec.state == "verifying" and is_expired(rec.lease)):
                done = self._verify(rec.session_id)
                if done is not None:
                    verified[done.session_id] = done
                    actions += 1
        if verified:  # what the verdicts wrote; nothing else of this run changes state by them
            sessions = [verified.get(rec.session_id, rec) for rec in sessions]
        replanned = 0
        for rec in sessions:
            if rec.state == "awaiting_replan":
                replanned += self._replan(rec.session_id)
        if replanned:
            sessions = self.sessions()
        resumed = self._resume_after_reopen(sessions)
        if resumed:
            sessions = self.sessions()
        actions += replanned + resumed
        self.reopen_edges(sessions)
        states = self.node_states(sessions)
        submitted: list[SessionRecord] = []
        latest = self.latest_by_node(sessions)
        ready = dagmod.ready_nodes(self.dag, states)
        if self.graph.schedule == "file_order":  # one at a time, first in file order
            in_flight = any(st == dagmod.RUNNING for st in states.values())
            ready = [] if in_flight else ready[:1]
        for node_id in ready:
            node = self.graph.get_node(node_id)
            target = self.world_target(node_id, latest)
            params, context = self.context_builder.build(goal=f"{self.graph.name}/{node.id}", skill=node.skill,
                                                         target=target or node.target, parameters=node.params,
                                                         scene=declared_scene(self.graph.scene),
                                                         observed=self.observed(node.params.get("object"), sessions),
                                                         run_id=self.run_id)
            context = with_calls(context, planner_calls(self.graph.provenance))  # the plan's model calls
            submitted.append(self.compiler.compile_node(node, parameters=params, context=context, target=target))
            if self.on_submit is not None:
                self.on_submit()
        actions += len(submitted)
        if submitted and self.defer_task_view:
            # the sessions this step left: the listing it made plus what it submitted (the
            # only change this step made after that listing)
            self.last_sessions = [*sessions, *submitted]
            self.task_view_stale = True
        else:
            self._write_task(self.sessions() if submitted else sessions)
        return actions

    def write_task(self) -> None:
        """Write what the last step deferred (see :attr:`defer_task_view`): the verdicts'
        LOG.md lines, then TASK.md with the run's sessions as that step left them,
        exactly what it would have written itself (without listing them again: a change
        made since, e.g. a supervisor's rejection, changes the run's active sessions,
        and the step that follows writes its own).

        Raises:
            DocumentError, ProtocolError, OSError: as for :meth:`append_owed_log` (TASK.md
                is still written).
        """
        try:
            self.append_owed_log()
        finally:
            self._write_task(self.last_sessions)

    def _verify(self, session_id: str) -> SessionRecord | None:
        """Judge ``session_id``'s latest attempt and persist the verdict; returns the record
        as written (None: another agent got there first). Its LOG.md line is owed to
        :meth:`step`."""
        ws = self.workspace
        with ws.session_lock(session_id):
            rec = ws.load_session(session_id)
            resume = rec.state == "verifying" and is_expired(rec.lease)
            if rec.state != "awaiting_verification" and not resume:
                return None  # another agent got there first
            rec.lease = new_lease(_AGENT_ID, ttl_s=_VERIFY_LEASE_S)
            lifecycle = SessionLifecycle(rec, persist=ws.save_session)
            if resume:
                ws.save_session(rec)
            else:
                lifecycle.fire("verify")
        attempt = rec.attempts[-1]
        evidence_dir = ws.root / attempt.evidence
        if self.keep_success_images:
            wait_for_images(evidence_dir)  # kept either way: the verdict references them
        evidence = self._evidence(evidence_dir)
        history = self.lineage(rec)
        judged, judged_evidence = self._judged(rec, evidence, history)
        verdict = self.verifier.verify(judged, judged_evidence, history=history, lineage_depth=len(history))
        if verdict.verdict == "success" and not self.keep_success_images:
            verdict = verdict.model_copy(update={"evidence": [r for r in verdict.evidence if r not in evidence.images]})
            self._prune_images(evidence)
        elif images_pending(evidence_dir):
            # Images are rendered off the critical path; a verdict other than success
            # keeps them and refers to them, so it is judged again once they exist.
            wait_for_images(evidence_dir)
            evidence = self._evidence(evidence_dir, fresh=True)
            verdict = self.verifier.verify(rec, evidence, history=history)
        attempt.verdict = verdict
        # model calls made for this session during its attempt (agent runtime) and its revision (a model reviser)
        calls_for = getattr(self.verifier.recovery, "calls_for", None)
        revised = [rec.session_id] + ([judged.session_id] if judged.session_id != rec.session_id else [])
        rec.context = with_calls(rec.context, trace_calls(evidence.trace, ref=evidence.refs("trace")[0]
                                                          if evidence.refs("trace") else None)
                                 + ([c for sid in revised for c in calls_for(sid)] if calls_for is not None else []))
        event = _EVENT_OF_VERDICT[verdict.verdict]
        rec.lease = None
        lifecycle.fire(event, reason=verdict.reason[:200])
        self._owed_log.append(LogEntry(at=utc_now(), session_id=rec.session_id, node=rec.node,
                                       event=f"verdict_{verdict.verdict}", state=rec.state, message=verdict.reason))
        logger.info("session %s verdict %s: %s", rec.session_id, verdict.verdict, verdict.reason)
        if self.consolidate:
            self._consolidate(rec, verdict, evidence, history)
        return rec

    def _judged(self, rec: SessionRecord, evidence: EvidenceBundle,
                history: list[SessionRecord]) -> tuple[SessionRecord, EvidenceBundle]:
        """What a verification judges: ``rec`` on its own evidence, or for an *another view*
        child the nearest acting ancestor on its evidence with this view's terminal snapshot."""
        if rec.recovery is None or rec.recovery.skill != "observe":
            return rec, evidence
        acting = next((h for h in reversed(history) if h.skill != "observe" and h.attempts
                       and h.attempts[-1].evidence), None)
        if acting is None:
            return rec, evidence
        try:
            base = load_evidence(self.workspace.root / acting.attempts[-1].evidence)
        except VerifierError as exc:
            logger.warning("acting session %s evidence unreadable: %s", acting.session_id, exc)
            return rec, evidence
        files = {**base.files, "terminal": f"../{evidence.directory.name}/{evidence.files.get('terminal', '')}"}
        merged = replace(base, terminal=evidence.terminal, files=files)
        return acting, merged

    def lineage(self, rec: SessionRecord) -> list[SessionRecord]:
        """``rec``'s ancestors along ``parent_session_id``, oldest first."""
        chain: list[SessionRecord] = []
        parent = rec.parent_session_id
        while parent:
            chain.append(self.workspace.load_session(parent))
            parent = chain[-1].parent_session_id
        return chain[::-1]

    def _conditions(self, rec: SessionRecord) -> Conditions:
        if rec.context is not None and rec.context.conditions:
            return Conditions.from_dict(rec.context.conditions)
        return self.context_builder.conditions(goal=f"{self.graph.name}/{rec.node}", skill=rec.skill,
                                               target=rec.target, parameters=rec.parameters,
                                               scene=declared_scene(rec.scene))

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

    def _evidence(self, directory, *, fresh: bool = False) -> EvidenceBundle:
        """:func:`load_evidence` of ``directory``, read again only when its ``bundle.yaml``
        is another file than last time (inode, modification time, size) or ``fresh``.

        A bundle is written once, ``bundle.yaml`` last, and replaced atomically if ever
        (a new inode); the verdict's read serves the observations that the next node's
        context is compiled from (a pick's bundle for its place: 7 ms on that hand-off).
        Keeps the latest :data:`_BUNDLES_KEPT` bundles; they are frozen and only read.

        Raises:
            VerifierError: as :func:`load_evidence`.
        """
        key = str(directory)
        try:
            stamp = file_identity(os.path.join(key, "bundle.yaml"))
        except OSError:
            stamp = None
        kept = self._bundles.get(key)
        if kept is not None and not fresh and stamp is not None and kept[0] == stamp:
            self._bundles.move_to_end(key)
            return kept[1]
        bundle = load_evidence(directory)
        if stamp is not None:
            self._bundles[key] = (stamp, bundle)
            self._bundles.move_to_end(key)
            while len(self._bundles) > _BUNDLES_KEPT:
                self._bundles.popitem(last=False)
        return bundle

    def _prune_images(self, evidence: EvidenceBundle) -> None:
        # Retention: a success's verdict, snapshots and trace stay; its RGB images go
        # (the marker first: images the runner writes later are then deleted by it).
        (evidence.directory / PRUNED_MARKER).touch()
        for ref in evidence.images:
            (self.workspace.root / ref).unlink(missing_ok=True)

    def _consolidate(self, rec: SessionRecord, verdict, evidence: EvidenceBundle,
                     history: list[SessionRecord]) -> None:
        """Verified outcomes only: lessons are confirmed or refuted, knowledge counted, procedures promoted."""
        conditions = self._conditions(rec)
        LessonBook(self.workspace).resolve(rec, verdict, conditions, history=history)
        info = self.context_builder.skills.get(rec.skill)
        # survival thresholds are the reflex's, owned by their trials (memory/deaths.py): not a
        # strategy of this skill, so never counted in its knowledge nor promoted with it
        strategy = {k: v for k, v in rec.parameters.items()
                    if info is not None and k in info.optional and k not in SITUATIONAL
                    and not (is_game_skill(rec.skill) and k in SURVIVAL_KEYS)}
        KnowledgeBase(self.workspace).record(
            rec, verdict, conditions, strategy=strategy,
            initial_state=initial_state_fingerprint(evidence.initial, conditions.object))
        learn_game_session(self.workspace, rec, verdict, evidence.trace, evidence.refs("trace"))  # no-op off games
        if verdict.verdict == "success":
            promote(self.workspace, self.promotion)

    def _replan(self, session_id: str) -> int:
        ws = self.workspace
        rec = ws.load_session(session_id)
        verdict = rec.attempts[-1].verdict if rec.attempts else None
        revision = verdict.revision if verdict is not None else None
        if revision is not None and revision.reopen:
            return self._reopen(rec, revision)
        history = self.lineage(rec)
        # an another-view session's child continues the acting session's parameters
        acting = rec if rec.skill != "observe" else next((h for h in reversed(history) if h.skill != "observe"), rec)
        node = self.graph.get_node(rec.node)
        if revision is not None and revision.skill:
            skill, params = revision.skill, dict(revision.parameters)
        else:  # the acting session's skill: the node's, or the one an earlier revision switched to
            skill = acting.skill if acting.skill != node.skill else None
            params = {**acting.parameters, **(revision.parameters if revision else {})}
        limits = {**acting.limits.model_dump(), **(revision.limits if revision else {})}
        # a re-target moves the node (and its later children) to the selector's other target
        target = revision.target if revision is not None and revision.target else \
            (acting.target if acting.target != node.target else None)
        child = self.compiler.compile_node(node, parent=rec, parameters=params, limits=limits, context=acting.context,
                                           recovery=revision, skill=skill, target=target)
        with ws.session_lock(session_id):
            rec = ws.load_session(session_id)
            rec.child_session_ids.append(child.session_id)
            SessionLifecycle(rec, persist=ws.save_session).fire("replanned", reason=f"child {child.session_id}")
        # another view only looks again (no correction to learn); a skill switch or re-target is one
        if self.consolidate and revision is not None and verdict.diagnosis is not None and revision.skill != "observe":
            LessonBook(ws).propose(parent=acting, child=child, diagnosis=verdict.diagnosis, revision=revision,
                                   conditions=self._conditions(acting))
        return 1

    def _reopen(self, rec: SessionRecord, revision) -> int:
        """Re-open ``revision.reopen`` upstream of ``rec`` (a re-pick); ``rec``'s node runs
        again once it succeeded (:meth:`_resume_after_reopen`)."""
        ws = self.workspace
        upstream = self.latest_by_node().get(revision.reopen)
        node = self.graph.get_node(revision.reopen)
        base = dict(upstream.parameters) if upstream is not None else dict(node.params)
        params = {**base, **revision.parameters}  # e.g. the slip's firmer grip, applied to the re-pick
        repick = self.compiler.compile_node(node, parent=upstream, parameters=params,
                                            context=upstream.context if upstream is not None else None,
                                            recovery=revision, target=upstream.target if upstream is not None else None)
        verdict = rec.attempts[-1].verdict if rec.attempts else None
        if self.consolidate and revision.parameters and upstream is not None and verdict is not None \
                and verdict.diagnosis is not None:
            LessonBook(ws).propose(parent=upstream, child=repick, diagnosis=verdict.diagnosis, revision=revision,
                                   conditions=self._conditions(upstream))
        with ws.session_lock(rec.session_id):
            rec = ws.load_session(rec.session_id)
            rec.child_session_ids.append(repick.session_id)
            SessionLifecycle(rec, persist=ws.save_session).fire(
                "replanned", reason=f"re-opened {revision.reopen} as {repick.session_id}")
        logger.info("session %s: re-opened upstream node %s as %s", rec.session_id, revision.reopen,
                    repick.session_id)
        return 1

    def _write_task(self, sessions: list[SessionRecord] | None = None) -> None:
        sessions = self.sessions() if sessions is None else sessions
        self.last_sessions = sessions
        self.task_view_stale = False
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

        # TASK.md is a view derived from the session files on every step: atomic, not fsynced.
        self.workspace.update("TASK", apply, durable=False)

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

    def succeeded(self) -> bool:
        """True when every node's latest session succeeded."""
        return all(state == dagmod.SUCCEEDED for state in self.node_states().values())
